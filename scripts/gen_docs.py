"""Regenerate the generated parts of the docs from the code and the committed results.

    python scripts/gen_docs.py          # rewrite in place
    python scripts/gen_docs.py --check  # exit 1 if a generated part is stale (used by the tests)

Generated parts sit between ``<!-- name -->`` and ``<!-- /name -->`` markers:

* ``docs/scenario.md`` ``config-table``: every EnvConfig key, type, default and meaning;
* ``docs/scenario.md`` ``calibration``: results/calibration.json as a table;
* ``docs/training.md`` ``train-config``: every key of a run (``TrainConfig``);
* ``docs/algorithms/*.md`` ``settings-ALGO``: each method's settings, presets and aids.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from pes.algos import ALGOS  # noqa: E402
from pes.learn.config import TrainConfig  # noqa: E402
from pes.learn.protocol import PROTOCOLS  # noqa: E402
from pes.sim.config import EnvConfig  # noqa: E402
from pes.strict import field_table  # noqa: E402


def _calibration_table() -> str:
    path = ROOT / "results" / "calibration.json"
    if not path.is_file():
        return "(run the command above to fill this table)"
    report = json.loads(path.read_text())
    rows = [
        "| pursuers | success rate | mean episode steps | crashes / episode | episodes |",
        "| --- | --- | --- | --- | --- |",
    ]
    for name, r in report["results"].items():
        rows.append(
            f"| {name} | {100 * r['success_rate']:.1f} % ± {100 * r['success_rate_ci95']:.1f} "
            f"| {r['mean_steps']:.0f} | {r['mean_crashes']:.2f} | {r['episodes']} |"
        )
    rows.append("")
    rows.append(
        f"Measured {report['date']} with `{report['command']}` "
        f"({report['machine']['cpu_count']} CPU cores, torch {report['machine']['torch']}); "
        "± is the 95 % interval."
    )
    return "\n".join(rows)


def _learner_table(algo: str) -> str:
    """The method's settings (its config dataclass) and its presets' values of them."""
    cls = ALGOS[algo]
    lines = [field_table(cls.Config), ""]
    for name, preset in cls.PRESETS.items():
        keys = {k: v for k, v in preset.items() if k not in ("env", "protocol")}
        shown = ", ".join(f"`{k}={v}`" for k, v in keys.items())
        lines.append(f"* preset `{name}`: {shown or 'the defaults'}")
    lines.append(
        f"* default protocol: `{cls.default_protocol}` (the `paper` preset: `paper`); "
        "aids applied: " + ", ".join(f"`{k}` {v}" for k, v in cls.aids(PROTOCOLS["pes"]).items())
    )
    return "\n".join(lines)


def _run_keys_table() -> str:
    """The run's keys; its ``protocol`` and ``learner`` sections are described beside it."""
    rows = field_table(TrainConfig).splitlines()
    return "\n".join(r for r in rows if not r.startswith(("| `protocol`", "| `learner`")))


ALGO_PAGES = {
    "cbc-tp": "cbc_tp",
    "cbc": "cbc_tp",
    "maddpg": "maddpg",
    "ddpg": "ddpg",
    "bicnet": "bicnet",
    "ppo": "ppo",
    "mappo": "mappo",
    "maac": "maac",
    "evader-ddpg": "evader_ddpg",
}
"""Method -> its page under docs/algorithms/ (CBC Net's settings are on CBC-TP Net's)."""

GENERATED = {
    ("docs/scenario.md", "config-table"): lambda: field_table(EnvConfig),
    ("docs/scenario.md", "calibration"): _calibration_table,
    ("docs/training.md", "train-config"): lambda: _run_keys_table(),
    **{
        (f"docs/algorithms/{page}.md", f"settings-{algo}"): (lambda a=algo: _learner_table(a))
        for algo, page in ALGO_PAGES.items()
    },
}


def render(text: str, name: str, body: str) -> str:
    pattern = re.compile(rf"(<!-- {name} -->\n).*?(<!-- /{name} -->)", re.S)
    if not pattern.search(text):
        raise SystemExit(f"markers for '{name}' not found")
    return pattern.sub(lambda m: m.group(1) + body.strip() + "\n" + m.group(2), text)


def main() -> int:
    check = "--check" in sys.argv
    stale = []
    for (file, name), make in GENERATED.items():
        path = ROOT / file
        text = path.read_text()
        new = render(text, name, make())
        if new != text:
            stale.append(f"{file}:{name}")
            if not check:
                path.write_text(new)
    if check and stale:
        print("stale generated docs: " + ", ".join(stale) + " (run python scripts/gen_docs.py)")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

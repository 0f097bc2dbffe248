"""Ship a trained policy inside the package, with its model card.

    python scripts/ship_model.py evader-ddpg runs/evader/best_policy.pt \
        --command "pes train --algo evader-ddpg ..."
    python scripts/ship_model.py evader-ddpg-paper runs/evader-snap/snapshots/epNNNNNN.pt \
        --command "pes train --algo evader-ddpg ... && python scripts/pick_evader.py ..."
    python scripts/ship_model.py cbc-tp runs/cbc_tp/best_policy.pt --command "pes train ..."
    python scripts/ship_model.py cbc-tp --card-only   # the card again, from the saved numbers

Copies the policy file to ``src/pes/models/`` (given a training checkpoint, writes a policy
file of its acting networks, the actor and TP Net, with the checkpoint's counters), evaluates
it over ``--episodes`` episodes with the paper's protocol (disturbance on,
``crash_mode="disable"``), and writes the model card (``src/pes/models/NAME.md``) and the raw
numbers (``results/shipped_NAME.json``):

* an evader (``evader-ddpg-paper``, ``evader-ddpg``): PID(PF) pursuers against it, beside
  PID(PF) against the scripted ``flee`` evader;
* the swarm: against the default evader (``evader-ddpg-paper``) with 0, 1 and 2 pursuers
  damaged (Table VI), against ``flee``, and against the fully trained evader (``evader-ddpg``)
  at its 12 m/s and with its top speed capped below (the speeds of
  ``pes.experiments.calibration``, where PID(PF)'s numbers for the same evaders are).

The swarm's card also quotes what its ``quick`` preset captures when trained from scratch, from
the reproduction in ``results/quick/evals.json``: rewrite the card with ``--card-only`` whenever
that reproduction changes (a test holds the committed card to it).
"""

from __future__ import annotations

import argparse
import json
import shlex
import shutil
import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from pes.algos.loading import describe, load_pursuer_policy  # noqa: E402
from pes.evaluate import evaluate  # noqa: E402
from pes.experiments.calibration import (  # noqa: E402
    EVADER_SPEEDS,
    PAPER_EVADER_CASE,
    evader_speed_case,
)
from pes.experiments.report import over_seeds  # noqa: E402
from pes.learn.checkpoint import (  # noqa: E402
    CHECKPOINT_FORMAT,
    POLICY_FORMAT,
    load_file,
    save_policy_file,
)
from pes.models import MODELS_DIR, SHIPPED  # noqa: E402
from pes.policies import PIDPotentialField  # noqa: E402
from pes.sim.bench import machine_info  # noqa: E402
from pes.sim.config import SHIPPED_EVADERS, EnvConfig  # noqa: E402

PAPER_TABLE_VI = {0: (98.8, 132), 1: (95.6, 212), 2: (86.7, 308)}
PAPER_PID_PF = 27.3  # Table IV: PID(PF)'s success rate (%) against the paper's evader


ACTING_MODULES = ("actor", "tp")  # what every learner's policy_modules() returns, at most


def ship_file(source: str, target: Path) -> None:
    """Copy a policy file to ``target``; of a checkpoint, keep only the acting networks."""
    obj = load_file(source, (POLICY_FORMAT, CHECKPOINT_FORMAT))
    if obj["format"] == POLICY_FORMAT:
        shutil.copyfile(source, target)
        return
    progress = obj["progress"]
    meta = {k: progress[k] for k in ("episodes", "env_steps", "updates") if k in progress}
    meta["wall_s"] = round(float(progress.get("wall_s", 0.0)), 1)
    meta["seed"] = obj["train_config"]["seed"]
    meta["torch"] = str(obj.get("torch", "unknown"))  # the torch that wrote the checkpoint
    meta["from_checkpoint"] = True
    policy = {k: v for k, v in obj["modules"].items() if k in ACTING_MODULES}
    save_policy_file(target, obj["algo"], obj["train_config"], obj["env_config"], policy, meta)


def run(policy, cfg: EnvConfig, episodes: int, seed: int) -> dict:
    result = evaluate(
        policy, cfg, episodes=episodes, num_envs=100, seed=seed, progress=True, compile=True
    )
    return result.summary()


def pid_pf_lines() -> list[str]:
    """Model-card lines: PID(PF) against the same evaders as the swarm -- the default one and
    the fully trained one at the capped speeds -- from ``results/calibration.json`` (its own seed
    and command), for the cases that file has."""
    path = ROOT / "results" / "calibration.json"
    if not path.is_file():
        return []
    rows = json.loads(path.read_text())["results"]
    found = [
        (speed, rows[evader_speed_case(speed)])
        for speed in EVADER_SPEEDS
        if evader_speed_case(speed) in rows
    ]
    parts = []
    if PAPER_EVADER_CASE in rows:
        parts.append(
            f"against `evader-ddpg-paper` {100 * rows[PAPER_EVADER_CASE]['success_rate']:.1f} %"
        )
    if found:
        parts.append(
            "against `evader-ddpg` at "
            + ", ".join(f"{speed:g} m/s {100 * row['success_rate']:.1f} %" for speed, row in found)
        )
    if not parts:
        return []
    # Where the paper's PID(PF) figure falls on the fully trained evader's speed axis.
    bracket = [
        f" The paper's {PAPER_PID_PF} % for PID(PF) lies between `evader-ddpg` at {slow:g} and "
        f"{fast:g} m/s."
        for (slow, a), (fast, b) in zip(found, found[1:])
        if a["success_rate"] >= PAPER_PID_PF / 100 > b["success_rate"]
    ]
    return [
        "",
        "PID(PF) (results/calibration.json, `python -m pes.experiments.calibration`): "
        + "; ".join(parts)
        + "."
        + "".join(bracket[:1]),
    ]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("name", choices=sorted(SHIPPED))
    parser.add_argument("policy", nargs="?", help="the policy file to ship")
    parser.add_argument("--command", help="the exact training command")
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=0, help="evaluation seed")
    parser.add_argument("--note", default="", help="how this file was chosen (model card)")
    parser.add_argument(
        "--card-only",
        action="store_true",
        help="ship and evaluate nothing: rewrite the model card from results/shipped_NAME.json "
        "(and, for the swarm, the reproduction in results/quick/)",
    )
    return parser


def reproduction_lines() -> list[str]:
    """Model-card lines: the swarm's ``quick`` preset trained from scratch, as the reproduction
    in ``results/quick/`` measured it (every finished CBC-TP Net seed, mean ± sample std), so
    that the card quotes what the README and results/README.md quote."""
    path = ROOT / "results" / "quick" / "evals.json"
    if not path.is_file():
        return []
    found = json.loads(path.read_text())
    trials = [t for _, t in sorted(found.items()) if (t.get("train") or {}).get("algo") == "cbc-tp"]
    if not trials:
        return []

    def stat(kind: str, field: str, scale: float, digits: int, unit: str = "") -> str:
        return over_seeds([t["evals"][kind][field] for t in trials], scale, digits, unit)

    steps = " or ".join(sorted({f"{t['train']['env_steps']:,}" for t in trials}))
    rows = [
        f"| {k} damaged | {stat(kind, 'success_rate', 100, 1, ' %')} "
        f"| {stat(kind, 'mean_steps', 1, 0)} |"
        for k, kind in enumerate(("table4", "damaged1", "damaged2"))
        if all(kind in t["evals"] for t in trials)
    ]
    return [
        "",
        "## The `quick` preset trained from scratch",
        "",
        f"This file is a longer training's pick. The `quick` preset itself ({steps} env steps "
        f"under the `pes` protocol, one torch thread), trained from scratch on {len(trials)} "
        "seeds by `pes reproduce table4 --methods cbc-tp --seeds 3 --out results/quick` and "
        "evaluated as the rows above (1000 episodes per row, disturbance on, crashes disable, "
        "against the default evader; the reproduction's evaluation seeds), captures "
        "(mean ± std over seeds; results/quick/evals.json):",
        "",
        "| setting | success rate | mean steps |",
        "| --- | --- | --- |",
        *rows,
    ]


def main() -> None:
    parser = build_parser()
    args = parser.parse_args()
    out = ROOT / "results" / f"shipped_{args.name.replace('-', '_')}.json"
    if args.card_only:
        if not out.is_file():
            parser.error(f"--card-only: {out} does not exist (ship the model first)")
        record = json.loads(out.read_text())
        shipped_args = parser.parse_args(shlex.split(record["eval_command"])[2:])
        write_card(shipped_args, record)
        return
    if args.policy is None or args.command is None:
        parser.error("give the policy file and --command (or --card-only)")
    torch.set_num_threads(2)

    target = MODELS_DIR / SHIPPED[args.name]
    ship_file(args.policy, target)
    info = describe(target)
    base = EnvConfig().for_evaluation()
    evals: dict[str, dict] = {}
    if args.name in SHIPPED_EVADERS:
        pid = PIDPotentialField(base)
        evals[f"pid-pf vs {args.name}"] = run(
            pid,
            base.replace(evader_policy="ddpg", evader_model=str(target)),
            args.episodes,
            args.seed,
        )
        evals["pid-pf vs flee evader"] = run(
            pid, base.replace(evader_policy="flee"), args.episodes, args.seed
        )
    else:
        evader = base.replace(evader_policy="ddpg")
        default = evader.evader_model
        for k in (0, 1, 2):
            cfg = evader.replace(damaged=k)
            policy, _ = load_pursuer_policy(target, cfg)
            evals[f"vs {default}, {k} damaged"] = run(policy, cfg, args.episodes, args.seed)
        cfg = base.replace(evader_policy="flee")
        policy, _ = load_pursuer_policy(target, cfg)
        evals["vs flee evader, 0 damaged"] = run(policy, cfg, args.episodes, args.seed)
        strong = evader.replace(evader_model="evader-ddpg")
        for speed in sorted(EVADER_SPEEDS, reverse=True):
            cfg = strong.replace(evader_max_speed=speed)
            policy, _ = load_pursuer_policy(target, cfg)
            evals[f"vs evader-ddpg at {speed:g} m/s, 0 damaged"] = run(
                policy, cfg, args.episodes, args.seed
            )

    machine = machine_info()
    meta = info["meta"]
    record = {
        "name": args.name,
        "source": args.policy,
        "command": args.command,
        "train_meta": meta,
        "machine": machine,
        "evaluations": evals,
        "eval_command": shlex.join(["python", "scripts/ship_model.py", *sys.argv[1:]]),
    }
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(record, indent=2) + "\n")
    write_card(args, record)
    print(
        json.dumps(
            {
                k: {m: v[m] for m in ("success_rate", "mean_steps", "mean_reward")}
                for k, v in evals.items()
            },
            indent=2,
        )
    )


def write_card(args: argparse.Namespace, record: dict) -> None:
    """Write the model card ``src/pes/models/NAME.md`` (:func:`card`)."""
    (MODELS_DIR / f"{SHIPPED[args.name].removesuffix('.pt')}.md").write_text(card(args, record))


def card(args: argparse.Namespace, record: dict) -> str:
    """The model card of the shipping ``args`` and the evaluation ``record`` (what
    ``results/shipped_NAME.json`` holds), as Markdown."""
    target = MODELS_DIR / SHIPPED[args.name]
    info = describe(target)
    cfg = info["train_config"]
    meta, machine, evals = record["train_meta"], record["machine"], record["evaluations"]
    default = EnvConfig().for_evaluation().replace(evader_policy="ddpg").evader_model
    lines = [
        f"# Model card: `{args.name}`",
        "",
        f"File: `src/pes/models/{SHIPPED[args.name]}` (a PES policy file, format version "
        f"{load_file(target, POLICY_FORMAT)['version']}).",
        "",
        "## How it was trained",
        "",
        f"* command: `{args.command}`",
        f"* algorithm `{cfg['algo']}`, preset `{cfg['preset']}`, protocol "
        f"`{cfg['protocol']['name']}`"
        + (
            " (the file predates training protocols: the command and the scenario overrides "
            "say how it trained)"
            if cfg["protocol"]["name"] == "unrecorded"
            else ""
        )
        + f", seed {cfg['seed']}; "
        f"scenario overrides: `{json.dumps(cfg['env'])}`",
        f"* {meta.get('episodes')} episodes, {meta.get('env_steps')} env steps, "
        f"{meta.get('updates')} updates, {meta.get('wall_s')} s wall time"
        + (
            f"; this file is the best log row's policy (episode {meta['best_at']})"
            if "best_at" in meta
            else ""
        ),
        *([f"* {args.note}"] if args.note else []),
        f"* hardware: {machine['cpu']}, {machine['cpu_count']} cores, torch {machine['torch']} "
        "(CPU)",
        "",
        f"## Evaluation ({args.episodes} episodes per row, disturbance on, crashes disable, "
        f"seed {args.seed})",
        "",
        "| setting | success rate | mean steps | average reward | crashes / episode |",
        "| --- | --- | --- | --- | --- |",
    ]
    for name, ev in evals.items():
        lines.append(
            f"| {name} | {100 * ev['success_rate']:.1f} % ± {100 * ev['success_rate_ci95']:.1f} "
            f"| {ev['mean_steps']:.1f} | {ev['mean_reward']:.3f} | {ev['mean_crashes']:.2f} |"
        )
    if args.name == "cbc-tp":
        lines += [
            "",
            f"`{default}` is the default opponent, the DDPG evader calibrated to the paper's "
            "(its model card); `evader-ddpg` is the fully trained DDPG evader, far stronger.",
            "",
            "Paper (Table VI, CBC-TP Net): "
            + ", ".join(f"{k} damaged {s} % / {t} steps" for k, (s, t) in PAPER_TABLE_VI.items())
            + ".",
            *pid_pf_lines(),
            *reproduction_lines(),
        ]
    else:
        lines += ["", "Success rate here is the pursuers' (lower means a stronger evader)."]
    name = f"shipped_{args.name.replace('-', '_')}.json"
    lines += ["", f"Made by: `{record['eval_command']}`; numbers in `results/{name}`.", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    main()

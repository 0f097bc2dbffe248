"""The report of a reproduction: Markdown tables beside the paper's numbers, PNG figures with
captions, and each trial's CSV log, from the finished trials of an output folder.

Files (in the output folder): ``table4.md``, ``table5.md``, ``table6.md``, ``figures.md`` (the
captions) with ``figures/*.png``, ``logs/<trial>.csv`` (each training run's progress log),
``evals.json`` (every evaluation's figures) and ``reproduce.json`` (settings, hardware, times).
Mean ± std is over seeds (the sample standard deviation; a single seed shows its value alone).
"""

from __future__ import annotations

import json
import shutil
from collections import Counter
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pes.algos.loading import load_pursuer_policy
from pes.experiments.budgets import (
    BUDGETS,
    DAMAGED,
    EVAL_SEED,
    eval_config,
    source_commit,
    write_json,
)
from pes.experiments.paper import LABELS, TABLE4, TABLE5, TABLE6
from pes.record import plot_trajectories, record_episode
from pes.sim.bench import machine_info
from pes.sim.config import EnvConfig


def _load(out: Path, specs: list[dict]) -> dict[str, dict]:
    done = {}
    for spec in specs:
        path = out / "trials" / spec["id"] / "done.json"
        if path.is_file():
            done[spec["id"]] = json.loads(path.read_text())
    return done


def _stats(values: list[float]) -> tuple[float, float]:
    arr = np.asarray(values, dtype=float)
    return float(arr.mean()), float(arr.std(ddof=1)) if len(arr) > 1 else 0.0


def over_seeds(values: list[float], scale: float = 1.0, digits: int = 1, unit: str = "") -> str:
    """``values`` (one per seed) times ``scale`` as the reports show them: "mean ± sample std",
    the value alone for one seed, "—" for none."""
    if not values:
        return "—"
    mean, std = _stats([v * scale for v in values])
    if len(values) == 1:  # one seed: no spread to show
        return f"{mean:.{digits}f}{unit}"
    return f"{mean:.{digits}f} ± {std:.{digits}f}{unit}"


def _fmt_count(values: list[int]) -> str:
    """A count with thousands separators: the one value, or mean ± std when they differ."""
    if not values:
        return "—"
    if len(set(values)) == 1:
        return f"{values[0]:,}"
    mean, std = _stats(values)
    return f"{mean:,.0f} ± {std:,.0f}"


def _training(specs: list[dict], done: dict, algo: str) -> list[dict]:
    """The training records (``env_steps``, ``cpu_s``, ...) of ``algo``'s finished trials."""
    records = (done.get(spec["id"]) for spec in specs if spec["algo"] == algo)
    return [rec["train"] for rec in records if rec is not None and rec.get("train")]


def _paper(value: float | None, scale: float = 1.0, digits: int = 1, unit: str = "") -> str:
    return "—" if value is None else f"{value * scale:.{digits}f}{unit}"


def _by_method(specs: list[dict], done: dict, kind: str = "table4") -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for spec in specs:
        rec = done.get(spec["id"])
        if rec is not None and "evals" in rec and kind in rec["evals"]:
            out.setdefault(spec["algo"], []).append(rec["evals"][kind])
    return out


def _changed(meta: dict) -> str:
    """`` with --set k=v ...`` for the settings every learner's training changed, else ``""``."""
    pairs = meta.get("overrides") or {}
    text = [f"`--set {k}={v if isinstance(v, str) else json.dumps(v)}`" for k, v in pairs.items()]
    return " with " + " ".join(text) if text else ""


def trained_on(trains: Iterable[dict[str, Any]]) -> str:
    """The CPUs that training runs spent their CPU minutes on, from their summaries' ``cpus``
    (a run resumed elsewhere names each machine): ``"A (3), unrecorded CPU (2)"``, the
    number of runs on each, most first, and the ``cpu_scale`` of the runs that had one
    (``"B (2, cpu_scale 1.19, 1.23)"``); ``""`` for no runs."""
    counts: Counter = Counter()
    scales: dict[str, set] = {}
    for train in trains:
        for cpu in train.get("cpus") or ["unrecorded CPU"]:
            counts[cpu] += 1
            if cpu_scale(train) != 1.0:
                scales.setdefault(cpu, set()).add(train["cpu_scale"])

    named = []
    for cpu, n in counts.most_common():
        if cpu in scales:
            named.append(
                f"{cpu} ({n}, cpu_scale {', '.join(f'{x:g}' for x in sorted(scales[cpu]))})"
            )
        else:
            named.append(f"{cpu} ({n})")
    return ", ".join(named)


def _task(meta: dict) -> str:
    """A sentence naming the EnvConfig keys that changed every method's task (training and
    evaluation alike: ``--scenario k=v``), else ``""``."""
    pairs = meta.get("scenario") or {}
    text = [
        f"`--scenario {k}={v if isinstance(v, str) else json.dumps(v)}`" for k, v in pairs.items()
    ]
    return "Every method's task, trained and evaluated: " + " ".join(text) + ". " if text else ""


def _header(title: str, meta: dict) -> list[str]:
    return [
        f"# {title}",
        "",
        f"Budget `{meta['budget']}`, every learner trained under the `{meta['protocol']}` "
        f"protocol{_changed(meta)}, {meta['seeds']} seed(s); each evaluation "
        f"{meta['eval_episodes']} episodes with disturbance, crashes disable, against the "
        f"{meta['evader']}. {_task(meta)}Mean ± std over seeds. Made by `{meta['command']}` "
        f"({meta['hardware']}).",
        "",
    ]


def load_outside(folder: str | Path | None) -> dict[str, list[dict]]:
    """Outside reference runs for Table IV (``python -m pes.benchmarl.reference``): the
    ``result.json`` of every subfolder of ``folder``, grouped by their method label ("MAPPO
    (BenchMARL)", ...), seeds in order. Nothing for None."""
    runs: dict[str, list[dict]] = {}
    if folder is None:
        return runs
    for path in sorted(Path(folder).glob("*/result.json")):
        record = json.loads(path.read_text())
        runs.setdefault(record["method"], []).append(record)
    for records in runs.values():
        records.sort(key=lambda r: r["seed"])
    return runs


def table4(
    specs: list[dict], done: dict, meta: dict, outside: dict[str, list[dict]] | None = None
) -> str | None:
    """Table IV of the finished trials beside the paper's, with the ``outside`` reference runs
    (:func:`load_outside`) as extra columns."""
    rows = _by_method(specs, done)
    methods = [m for m in LABELS if m in rows]
    outside = outside or {}
    if not methods and not outside:
        return None
    columns = {LABELS[m]: rows[m] for m in methods}
    columns.update({label: [r["eval"] for r in runs] for label, runs in outside.items()})
    paper_of = {LABELS[m]: TABLE4[m] for m in methods}
    lines = _header("Table IV: every method against the DDPG evader", meta)
    lines += [
        "| | " + " | ".join(columns) + " |",
        "| --- |" + " --- |" * len(columns),
    ]
    metrics = (
        ("success rate", "success_rate", 100.0, 1, " %"),
        ("episode steps", "mean_steps", 1.0, 0, ""),
        ("average reward", "mean_reward", 1.0, 3, ""),
    )
    for label, key, scale, digits, unit in metrics:
        ours = [
            over_seeds([r[key] for r in evals], scale, digits, unit) for evals in columns.values()
        ]
        paper = [
            _paper(paper_of[c][key], scale, digits, unit) if c in paper_of else "—" for c in columns
        ]
        lines.append(f"| {label} (PES) | " + " | ".join(ours) + " |")
        if not meta.get("scenario"):  # the paper's numbers are of its task, not of another
            lines.append(f"| {label} (paper) | " + " | ".join(paper) + " |")
    failures = (
        ("failed: swarm lost to crashes (PES)", "lost_rate", 100.0, 1, " %"),
        ("failed: step limit (PES)", "timeout_rate", 100.0, 1, " %"),
        ("crashes per episode (PES)", "mean_crashes", 1.0, 2, ""),
    )
    for label, key, scale, digits, unit in failures:
        ours = [
            over_seeds([r[key] for r in evals if key in r], scale, digits, unit)
            for evals in columns.values()
        ]
        lines.append(f"| {label} | " + " | ".join(ours) + " |")
    # What training cost: every learner gets the same env steps, not the same CPU time.
    costs = {LABELS[m]: _training(specs, done, m) for m in methods}
    costs.update(
        {
            label: [{"env_steps": r["frames"], "cpu_s": r.get("cpu_s")} for r in runs]
            for label, runs in outside.items()
        }
    )
    steps = [_fmt_count([c["env_steps"] for c in costs[col]]) for col in columns]
    minutes = [
        over_seeds(
            [reference_cpu_s(c) / 60 for c in costs[col] if c.get("cpu_s") is not None], digits=0
        )
        for col in columns
    ]
    lines.append("| training env steps (PES) | " + " | ".join(steps) + " |")
    lines.append("| training CPU minutes (PES) | " + " | ".join(minutes) + " |")
    # Evaluations disable a crashed pursuer; a crash curriculum that never switched trained the
    # learner under the other rule all run.
    ruled = [
        f"{sum(bool(c.get('crashes_disable')) for c in costs[col])} of {len(costs[col])}"
        if costs[col] and all("crashes_disable" in c for c in costs[col])
        else "—"
        for col in columns
    ]
    if any(r != "—" for r in ruled):
        lines.append(
            "| trained to crashes that disable, as evaluated (seeds) | " + " | ".join(ruled) + " |"
        )
    lines += [
        "",
        "Seeds per method: " + ", ".join(f"{c} {len(e)}" for c, e in columns.items()) + ".",
    ]
    if "cbc" in methods:
        lines.append("CBC Net (the ablation of §V-C) is not in the paper's Table IV.")
    if outside:
        frames = sorted({r["frames"] for runs in outside.values() for r in runs})
        episodes = sorted({r["eval"]["episodes"] for runs in outside.values() for r in runs})
        lines.append(
            "Outside columns (" + ", ".join(outside) + "): BenchMARL's own algorithm, MLP model "
            "and experiment configs on the task `pes/train` (the scenario, training reward and "
            f"disturbance of the `pes` protocol), {', '.join(f'{f:,}' for f in frames)} frames "
            "(env steps) per run, evaluated as the other columns (the same seeds; "
            f"{', '.join(map(str, episodes))} episodes); they do not get the `pes` protocol's "
            "other aids (PID(PF)'s demonstrations, the crash curriculum, the noise schedule, "
            "n-step targets, greedy environments). Commands: "
            + "; ".join(f"`{r['command']}`" for runs in outside.values() for r in runs)
            + "."
        )
        for label, runs in outside.items():
            for r in runs:
                if "diverged" in r:
                    lines.append(
                        f"{label}, seed {r['seed']}: training diverged ({r['diverged']}); "
                        f"its last checkpoint before that, at {r['frames']:,} frames, is evaluated."
                    )
    lines.append("")
    return "\n".join(lines)


def table5(specs: list[dict], done: dict, meta: dict) -> str | None:
    recs = [done[s["id"]]["table5"] for s in specs if s["kind"] == "tpnet" and s["id"] in done]
    if not recs:
        return None
    lines = _header("Table V: TP Net's prediction error", meta)

    def windows(key: str) -> str:  # each seed plays its own episodes: one count, or the range
        low, high = min(r[key] for r in recs), max(r[key] for r in recs)
        return f"{low:,}" if low == high else f"between {low:,} and {high:,}"

    lines[2] = (
        f"Budget `{meta['budget']}`, {len(recs)} seed(s): TP Net (horizon 5) trained on "
        f"{windows('train_windows')} windows of {recs[0]['pursuers']} pursuers against the "
        f"{meta['evader']}, measured on {windows('test_windows')} held-out windows. "
        "Errors in arena units (metres / arena side); see pes.experiments.tpnet. "
        f"Made by `{meta['command']}` ({meta['hardware']})."
    )
    lines += ["| | k = 1 | k = 2 | k = 3 | k = 4 | k = 5 |", "| --- |" + " --- |" * 5]
    for key in ("fde", "ade"):
        ours = [over_seeds([r[key][k] for r in recs], digits=4) for k in range(5)]
        const = [
            over_seeds([r["constant_position"][key][k] for r in recs], digits=4) for k in range(5)
        ]
        lines.append(f"| {key.upper()} (PES) | " + " | ".join(ours) + " |")
        lines.append(f"| {key.upper()} (paper) | " + " | ".join(f"{v:.3f}" for v in TABLE5[key]))
        lines[-1] += " |"
        lines.append(f"| {key.upper()} (evader stays put) | " + " | ".join(const) + " |")
    lines.append("")
    return "\n".join(lines)


def table6(specs: list[dict], done: dict, meta: dict) -> str | None:
    settings = {0: "table4", **{k: f"damaged{k}" for k in DAMAGED}}
    rows = {k: _by_method(specs, done, name).get("cbc-tp", []) for k, name in settings.items()}
    if not rows[0]:
        return None
    lines = _header("Table VI: CBC-TP Net with damaged pursuers", meta)
    lines += [
        "| pursuers damaged | success rate (PES) | success rate (paper) | episode steps (PES) "
        "| episode steps (paper) |",
        "| --- | --- | --- | --- | --- |",
    ]
    for k, recs in rows.items():
        lines.append(
            f"| {k} | {over_seeds([r['success_rate'] for r in recs], 100.0, 1, ' %')} "
            f"| {100 * TABLE6[k][0]:.1f} % "
            f"| {over_seeds([r['mean_steps'] for r in recs], digits=0)} | {TABLE6[k][1]} |"
        )
    lines.append("")
    return "\n".join(lines)


# --- figures ---------------------------------------------------------------------------------


def read_progress(path: Path) -> np.ndarray:
    """A run's ``progress.csv`` as a 1-D structured array, one record per log row (named by
    the header; empty when no row was logged yet)."""
    return np.atleast_1d(np.genfromtxt(path, delimiter=",", names=True))


def cpu_scale(train: dict[str, Any]) -> float:
    """A run's ``cpu_scale`` from its summary (1 for runs that trained on the reference CPU of
    their ``cpu_limit`` or did not record one)."""
    return train.get("cpu_scale", 1.0)


def reference_cpu_s(train: dict[str, Any]) -> float:
    """A run's CPU seconds counted on the reference CPU of its ``cpu_limit``: its ``cpu_s``
    divided by its :func:`cpu_scale`."""
    return train["cpu_s"] / cpu_scale(train)


def _curves(out: Path, specs: list[dict], done: dict) -> dict[str, list[np.ndarray]]:
    """Method -> each seed's progress log as a structured array, its ``cpu_s`` counted on the
    reference CPU (:func:`reference_cpu_s`)."""
    curves: dict[str, list] = {}
    for spec in specs:
        log = out / "trials" / spec["id"] / "run" / "progress.csv"
        if spec["kind"] == "train" and spec["id"] in done and log.is_file():
            rows = read_progress(log)
            if "cpu_s" in (rows.dtype.names or ()):
                rows["cpu_s"] /= cpu_scale(done[spec["id"]].get("train") or {})
            curves.setdefault(spec["algo"], []).append(rows)
    return curves


COLORS = {method: f"C{i}" for i, method in enumerate(LABELS)}
"""One matplotlib colour per method (by its place in Table IV), the same in every figure."""


def _band(
    ax,
    runs: list[np.ndarray],
    key: str,
    label: str,
    scale: float = 1.0,
    x: str = "episodes",
    x_scale: float = 1.0,
    color: str | None = None,
) -> None:
    """Mean ± std over ``runs`` of ``key`` × ``scale`` against the log column ``x`` ×
    ``x_scale`` (each run interpolated onto every run's x values, within its own range), in
    ``color`` (matplotlib's next colour when None)."""
    grid = np.unique(np.concatenate([r[x] * x_scale for r in runs]))
    grid = grid[grid <= min(float(r[x][-1]) * x_scale for r in runs)]
    ys = np.stack([np.interp(grid, r[x] * x_scale, r[key] * scale) for r in runs])
    mean = ys.mean(0)
    seeds = f"{len(runs)} seed" + ("s" if len(runs) > 1 else "")
    (line,) = ax.plot(grid, mean, label=f"{label} ({seeds})", color=color)
    if len(runs) > 1:
        std = ys.std(0, ddof=1)
        low, high = mean - std, mean + std
        if key == "success_rate":  # a rate: the band stays within 0 ... 100 %
            low, high = np.clip(low, 0.0, 100.0), np.clip(high, 0.0, 100.0)
        ax.fill_between(grid, low, high, color=line.get_color(), alpha=0.2)


def figures(out: Path, specs: list[dict], done: dict, meta: dict) -> list[tuple[str, str]]:
    """Write the PNG figures; returns (file, caption) pairs."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    folder = out / "figures"
    folder.mkdir(exist_ok=True)
    made: list[tuple[str, str]] = []
    curves = _curves(out, specs, done)
    training = (
        "training episodes (as each method trained: its exploration, its protocol's training "
        "reward, disturbance and crash rule of the moment), mean ± std over seeds "
        "(success-rate bands cut at 0 %), one point per log row; under the `pes` protocol the "
        "first rows are PID(PF)'s demonstration episodes (the log's `demonstrating` column; "
        "across many environments the first of them to end are the short ones, mostly captures)"
    )
    panels = (
        ("fig6_success_rate.png", "success_rate", "success rate (%)", 100.0, "Fig. 6"),
        ("fig7_average_reward.png", "avg_reward", "average reward", 1.0, "Fig. 7"),
        ("fig8_episode_steps.png", "episode_steps", "episode steps", 1.0, "Fig. 8"),
    )
    for name, key, ylabel, scale, paper_fig in panels:
        if not curves:
            break
        fig, ax = plt.subplots(figsize=(7, 4.5))
        for method in LABELS:
            if method in curves:
                _band(ax, curves[method], key, LABELS[method], scale, color=COLORS[method])
        ax.set_xlabel("episodes")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(folder / name, dpi=120)
        plt.close(fig)
        made.append((name, f"{paper_fig}: {ylabel} of every learned method over {training}."))

    if curves:
        made.append(_experience_and_compute(curves, folder, plt, training))
    if "cbc" in curves and "cbc-tp" in curves:
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
        for ax, (key, ylabel, scale) in zip(
            axes, (("success_rate", "success rate (%)", 100.0), ("avg_reward", "average reward", 1))
        ):
            for method in ("cbc", "cbc-tp"):
                _band(ax, curves[method], key, LABELS[method], scale, color=COLORS[method])
            ax.set_xlabel("episodes")
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(folder / "fig9_10_cbc_tp_vs_cbc.png", dpi=120)
        plt.close(fig)
        made.append(
            (
                "fig9_10_cbc_tp_vs_cbc.png",
                "Figs. 9-10: success rate and average reward of CBC-TP Net and CBC Net over "
                f"{training}.",
            )
        )
    made += _trajectory_figures(out, specs, done, meta, folder, plt)
    return made


def _experience_and_compute(curves: dict, folder: Path, plt, training: str) -> tuple[str, str]:
    """Every learner's training success against env steps and against CPU minutes (runs that
    logged ``cpu_s``), side by side: the comparison at equal experience and at equal compute."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    panels = (("env_steps", 1e-6, "env steps (millions)"), ("cpu_s", 1 / 60, "CPU minutes"))
    for ax, (x, x_scale, xlabel) in zip(axes, panels):
        for method in LABELS:
            runs = [r for r in curves.get(method, []) if x in (r.dtype.names or ())]
            if runs:
                _band(ax, runs, "success_rate", LABELS[method], 100.0, x, x_scale, COLORS[method])
        ax.set_xlabel(xlabel)
        ax.set_ylabel("success rate (%)")
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    fig.tight_layout()
    name = "learning_curves.png"
    fig.savefig(folder / name, dpi=120)
    plt.close(fig)
    caption = (
        "Success rate of every learned method against the env steps it trained on (equal "
        "experience) and against the CPU minutes its process used (equal compute; runs that "
        "logged them; a run on a slower CPU than the reference counts its CPU time divided by "
        f"its `cpu_scale`), over {training}."
    )
    return name, caption


def _seed0(specs: list[dict], done: dict, algo: str) -> Path | None:
    """The policy file (relative to the output folder) of ``algo``'s first finished seed."""
    for spec in specs:
        if spec["algo"] == algo and spec["id"] in done:
            return Path("trials") / spec["id"] / "run" / "policy.pt"
    return None


def episode_config(meta: dict, damaged: int = 0) -> EnvConfig:
    """The evaluation scenario of a reproduction's figures: its budget's evaluation with
    ``damaged`` pursuers disabled, on its task (``meta["scenario"]``, e.g. the positive
    control's evader at 8 m/s)."""
    return eval_config(BUDGETS[meta["budget"]], damaged, meta.get("scenario"))


def _trajectory_figures(out, specs, done, meta, folder, plt) -> list[tuple[str, str]]:
    seed = EVAL_SEED
    made = []

    def episode(algo: str, damaged: int):
        cfg = episode_config(meta, damaged)
        policy = load_pursuer_policy(out / _seed0(specs, done, algo), cfg)[0]
        return record_episode(policy, cfg, seed=seed)

    if _seed0(specs, done, "cbc-tp") and _seed0(specs, done, "cbc"):
        fig, axes = plt.subplots(1, 2, figsize=(12, 6))
        plot_trajectories(episode("cbc-tp", 0), axes[0], title="CBC-TP Net (with TP Net)")
        plot_trajectories(episode("cbc", 0), axes[1], title="CBC Net (without TP Net)")
        fig.tight_layout()
        fig.savefig(folder / "fig11_trajectories_tp.png", dpi=110)
        plt.close(fig)
        made.append(
            (
                "fig11_trajectories_tp.png",
                "Fig. 11: one evaluation episode (the same start, seed "
                f"{seed}) played by CBC-TP Net (left; thin lines: TP Net's predicted evader path) "
                "and CBC Net (right), seed-0 policies, against the DDPG evader.",
            )
        )
    if _seed0(specs, done, "cbc-tp"):
        fig, axes = plt.subplots(1, len(DAMAGED), figsize=(6 * len(DAMAGED), 6))
        for ax, k in zip(np.atleast_1d(axes), DAMAGED):
            plot_trajectories(episode("cbc-tp", k), ax, title=f"CBC-TP Net, {k} damaged")
        fig.tight_layout()
        fig.savefig(folder / "fig12_trajectories_damaged.png", dpi=110)
        plt.close(fig)
        made.append(
            (
                "fig12_trajectories_damaged.png",
                f"Fig. 12: CBC-TP Net (seed-0 policy) with {' and '.join(map(str, DAMAGED))} "
                "pursuers damaged at the start (grey crosses), one evaluation episode each.",
            )
        )
        steps = {}
        for k, name in ((0, "table4"), *((k, f"damaged{k}") for k in DAMAGED)):
            steps[k] = []
            for spec in specs:
                path = out / "trials" / spec["id"] / f"eval_{name}.json"
                if spec["algo"] == "cbc-tp" and path.is_file():
                    steps[k] += json.loads(path.read_text())["per_episode"]["steps"]
        fig, ax = plt.subplots(figsize=(6, 4.5))
        ax.boxplot([steps[k] for k in steps], showmeans=True)
        ax.set_xticks(range(1, len(steps) + 1), [f"{k} damaged" for k in steps])
        ax.set_ylabel("episode steps")
        ax.grid(alpha=0.3, axis="y")
        fig.tight_layout()
        fig.savefig(folder / "fig13_damaged_steps.png", dpi=120)
        plt.close(fig)
        made.append(
            (
                "fig13_damaged_steps.png",
                "Fig. 13: episode steps of CBC-TP Net with 0 / 1 / 2 pursuers damaged, every "
                "evaluation episode of every seed (failures count at the step limit; triangles: "
                "means).",
            )
        )
    return made


def _resolved_config(folder: Path) -> dict | None:
    """The full configuration a trial's training ran with (its ``run/config.yaml``)."""
    path = folder / "run" / "config.yaml"
    return yaml.safe_load(path.read_text()) if path.is_file() else None


def write_report(
    out: Path,
    specs: list[dict],
    target: str,
    budget: str,
    seeds: int,
    command: str,
    seconds: float,
    protocol: str = "pes",
    outside: str | Path | None = None,
    overrides: dict[str, Any] | None = None,
    scenario: dict[str, Any] | None = None,
) -> list[str]:
    """Write every table and figure the finished trials allow; returns the files written.
    ``outside``: a folder of outside reference runs for Table IV (:func:`load_outside`).
    ``overrides``: the ``--set`` keys every learner's training changed (named in the tables).
    ``scenario``: the EnvConfig keys that changed every method's task (named in the tables)."""
    done = _load(out, specs)
    for spec in specs:  # the crash rule each training ended under, from its last log row
        train = (done.get(spec["id"]) or {}).get("train")
        log = out / "trials" / spec["id"] / "run" / "progress.csv"
        if train and "crashes_disable" not in train and log.is_file():
            rows = read_progress(log)
            if len(rows) and "crashes_disable" in (rows.dtype.names or ()):
                train["crashes_disable"] = bool(rows["crashes_disable"][-1] == 1)
    references = load_outside(outside)
    machine = machine_info()
    trains = [rec["train"] for rec in done.values() if rec.get("train")]  # the learner trials
    cfg = eval_config(BUDGETS[budget], scenario=scenario)
    meta = {
        "budget": budget,
        "protocol": protocol,
        "overrides": dict(overrides or {}),
        "scenario": dict(scenario or {}),
        "seeds": seeds,
        "eval_episodes": BUDGETS[budget].eval_episodes,
        "evader": (
            f"DDPG evader `{cfg.evader_model}`"
            if cfg.evader_policy == "ddpg"
            else f"`{cfg.evader_policy}` evader"
        ),
        "command": command or f"pes reproduce {target} --budget {budget} --seeds {seeds}",
        "hardware": f"{machine['cpu']}, {machine['cpu_count']} cores, torch {machine['torch']}"
        + (f"; trials trained on {cpus}" if (cpus := trained_on(trains)) else ""),
    }
    written = []
    tables = {
        "table4": lambda: table4(specs, done, meta, references),
        "table5": lambda: table5(specs, done, meta),
        "table6": lambda: table6(specs, done, meta),
    }
    for name, make in tables.items():
        if target in (name, "all") or (target == "figures" and name == "table4"):
            text = make()
            if text is not None:
                (out / f"{name}.md").write_text(text)
                written.append(f"{name}.md")
    if target in ("figures", "all"):
        made = figures(out, specs, done, meta)
        lines = ["# Figures", "", f"Made by `{meta['command']}` ({meta['hardware']}).", ""]
        for name, caption in made:
            lines += [f"## {name}", "", f"![{name}](figures/{name})", "", caption, ""]
        (out / "figures.md").write_text("\n".join(lines))
        written += ["figures.md", *(f"figures/{n}" for n, _ in made)]

    logs = out / "logs"
    evals: dict[str, Any] = {}
    for spec in specs:
        if spec["id"] not in done:
            continue
        src = out / "trials" / spec["id"] / "run" / "progress.csv"
        if src.is_file():
            logs.mkdir(exist_ok=True)
            shutil.copyfile(src, logs / f"{spec['id']}.csv")
        rec = done[spec["id"]]
        evals[spec["id"]] = {k: rec.get(k) for k in ("evals", "table5", "train")}
    write_json(out / "evals.json", evals)
    write_json(
        out / "reproduce.json",
        {
            **meta,
            "target": target,
            "trials": [s["id"] for s in specs],
            "finished": sorted(done),
            "seconds_this_invocation": round(seconds, 1),
            "training_seconds": {
                k: v["train"]["wall_s"] for k, v in evals.items() if v.get("train")
            },
            "trial_seconds": {k: done[k].get("seconds_this_run") for k in evals},
            "commit": source_commit(),
            "trial_commits": {k: done[k].get("commit") for k in evals},
            "trial_configs": {k: _resolved_config(out / "trials" / k) for k in evals},
            "outside": {
                "folder": str(outside) if outside is not None else None,
                "runs": [
                    {k: r[k] for k in ("method", "seed", "frames", "command")}
                    for runs in references.values()
                    for r in runs
                ],
            },
            "machine": machine,
        },
    )
    return written + ["evals.json", "reproduce.json"]

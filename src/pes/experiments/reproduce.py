"""``pes reproduce``: run the paper's experiments and write its tables and figures (SPEC §4).

    pes reproduce all --budget quick --seeds 3 --out results/quick

Each target needs a set of trials (:mod:`pes.experiments.trials`): Table IV every method of
:data:`pes.experiments.paper.METHODS` available here; Table V the TP Net trials; Table VI the
CBC-TP Net trials; the figures the training trials. Trials run as Ray Tune trials (one CPU each;
a local Ray instance, or the cluster at ``--ray-address``), or one after the other in this
process when Ray is not installed or ``--no-ray`` is given. Re-running the command skips the
finished trials and resumes the interrupted ones from their checkpoints. The report
(:mod:`pes.experiments.report`) is then written from whatever trials are finished.
"""

from __future__ import annotations

import importlib.util
import os
import time
from pathlib import Path
from typing import Any

from tqdm import tqdm

from pes.algos import ALGOS
from pes.errors import ConfigError
from pes.experiments.paper import METHODS
from pes.experiments.report import write_report
from pes.experiments.trials import BUDGETS, make_trials, run_trial

TARGETS = ("table4", "table5", "table6", "figures", "all")


def available_methods() -> list[str]:
    """The methods of Table IV (and CBC Net) that this installation can train."""
    return [m for m in METHODS if m == "pid-pf" or m in ALGOS]


def trials_for(target: str, methods: list[str], seeds: int, budget: str) -> list[dict]:
    """The trial specs a target needs."""
    if target not in TARGETS:
        raise ConfigError(f"target must be one of {', '.join(TARGETS)}, got '{target}'")
    if target == "table6":
        methods = [m for m in methods if m == "cbc-tp"]
        if not methods:
            raise ConfigError("table6 needs the cbc-tp method")
    elif target == "table5":
        methods = []
    return make_trials(methods, seeds, budget, tpnet=target in ("table5", "all"))


class SweepProgress:
    """The progress of the whole sweep: trials done, running and left, with a time estimate
    (tqdm's, from the rate of finished trials)."""

    def __init__(self, total: int, skipped: int, enabled: bool) -> None:
        self.running: set[str] = set()
        self.left = total - skipped
        self.bar = tqdm(
            total=total,
            initial=skipped,
            unit="trial",
            desc="reproduce",
            disable=not enabled,
            dynamic_ncols=True,
        )
        self._show()

    def _show(self) -> None:
        names = ", ".join(sorted(self.running)[:3]) + (" ..." if len(self.running) > 3 else "")
        self.bar.set_postfix_str(
            f"running {len(self.running)}{': ' + names if names else ''}, left {self.left}"
        )

    def start(self, trial: str) -> None:
        self.running.add(trial)
        self.left -= 1
        self._show()

    def finish(self, trial: str) -> None:
        self.running.discard(trial)
        self.bar.update(1)
        self._show()

    def close(self) -> None:
        self.bar.close()


def run_sequential(specs: list[dict], out: Path, view: SweepProgress) -> None:
    """Every trial in this process, one after the other (all torch threads to each)."""
    for spec in specs:
        view.start(spec["id"])
        run_trial(spec, out)
        view.finish(spec["id"])


_ACTIVE_VIEW: SweepProgress | None = None
"""The progress view of the Ray sweep in flight (see :func:`run_ray`)."""


def _on_trial(event: str, trial: str) -> None:
    if _ACTIVE_VIEW is not None:
        getattr(_ACTIVE_VIEW, event)(trial)


def run_ray(
    specs: list[dict], out: Path, address: str | None, view: SweepProgress, parallel: int = 0
) -> None:
    """Every trial as a Ray Tune trial with one CPU (and one torch thread), at most ``parallel``
    at once (0: as many as the cluster's CPUs). With ``address``, the output folder must be on
    storage that every node of the cluster sees."""
    import ray  # noqa: PLC0415
    from ray import tune  # noqa: PLC0415

    class Progress(tune.Callback):
        # Tune pickles its callbacks with the experiment's state: the view (it holds a terminal
        # handle) is reached through a module function, which pickles by reference.
        def on_trial_start(self, iteration, trials, trial, **info):
            _on_trial("start", trial.config["spec"]["id"])

        def on_trial_complete(self, iteration, trials, trial, **info):
            _on_trial("finish", trial.config["spec"]["id"])

        def on_trial_error(self, iteration, trials, trial, **info):
            _on_trial("finish", trial.config["spec"]["id"])

    def trainable(config: dict[str, Any]) -> None:
        run_trial(config["spec"], Path(config["out"]), threads=1)
        tune.report({"finished": 1})

    global _ACTIVE_VIEW
    _ACTIVE_VIEW = view
    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")
    ray.init(
        address=address,
        ignore_reinit_error=True,
        include_dashboard=False,
        log_to_driver=False,
        configure_logging=False,
    )
    try:
        tuner = tune.Tuner(
            tune.with_resources(trainable, {"cpu": 1}),
            param_space={"spec": tune.grid_search(specs), "out": str(out.resolve())},
            run_config=tune.RunConfig(
                name=f"reproduce-{int(time.time())}",
                storage_path=str((out / "ray").resolve()),
                verbose=0,
                callbacks=[Progress()],
            ),
            tune_config=tune.TuneConfig(max_concurrent_trials=parallel or None),
        )
        results = tuner.fit()
        failed = [r for r in results if r.error is not None]
        if failed:
            raise RuntimeError(f"{len(failed)} trial(s) failed; first: {failed[0].error}")
    finally:
        _ACTIVE_VIEW = None
        ray.shutdown()


def reproduce(
    target: str,
    budget: str = "quick",
    seeds: int = 3,
    out: str | Path = "results/reproduce",
    methods: list[str] | None = None,
    ray_address: str | None = None,
    use_ray: bool | None = None,
    progress: bool = True,
    command: str = "",
    parallel: int = 0,
    report_only: bool = False,
) -> dict[str, Any]:
    """Run the trials of ``target`` and write its report into ``out``; returns a summary.

    ``use_ray``: None uses Ray when it is installed; False runs the trials in this process.
    ``parallel``: at most this many trials at once under Ray (0: one per CPU).
    ``report_only``: run nothing; write the report of the trials finished so far.
    """
    if budget not in BUDGETS:
        raise ConfigError(f"budget must be one of {', '.join(BUDGETS)}, got '{budget}'")
    if seeds < 1:
        raise ConfigError(f"seeds must be at least 1, got {seeds}")
    have_ray = importlib.util.find_spec("ray") is not None
    if use_ray and not have_ray:
        raise ConfigError("Ray is not installed: pip install 'pes[ray]' (or run with --no-ray)")
    if ray_address and not have_ray:
        raise ConfigError("--ray-address needs Ray: pip install 'pes[ray]'")
    use_ray = have_ray if use_ray is None else use_ray
    methods = list(methods) if methods else available_methods()
    specs = trials_for(target, methods, seeds, budget)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    todo = [s for s in specs if not (out / "trials" / s["id"] / "done.json").is_file()]
    finished = len(specs) - len(todo)
    if report_only:
        todo = []
    start = time.time()
    view = SweepProgress(len(specs), finished, progress and bool(todo))
    try:
        if todo and use_ray:
            run_ray(todo, out, ray_address, view, parallel)
        elif todo:
            run_sequential(todo, out, view)
    finally:
        view.close()
    report = write_report(out, specs, target, budget, seeds, command, time.time() - start)
    return {
        "target": target,
        "budget": budget,
        "seeds": seeds,
        "out": str(out),
        "runner": "ray" if use_ray else "sequential",
        "trials": len(specs),
        "skipped": finished,
        "ran": len(todo),
        "unfinished": len(specs) - finished - len(todo),
        "seconds": round(time.time() - start, 1),
        "files": report,
    }

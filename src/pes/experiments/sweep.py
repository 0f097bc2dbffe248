"""Running a set of resumable trials: one after the other in this process, or as Ray Tune
trials (one CPU and one torch thread each), with one progress bar for the whole set. Used by
``pes reproduce`` and ``pes tune``."""

from __future__ import annotations

import importlib.util
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tqdm import tqdm

from pes.errors import ConfigError, TrialsFailedError


def choose_runner(use_ray: bool | None, ray_address: str | None) -> bool:
    """Whether to run under Ray: ``use_ray`` None means when Ray is installed."""
    have_ray = importlib.util.find_spec("ray") is not None
    if use_ray and not have_ray:
        raise ConfigError("Ray is not installed: pip install 'pes[ray]' (or run with --no-ray)")
    if ray_address and not have_ray:
        raise ConfigError("--ray-address needs Ray: pip install 'pes[ray]'")
    return have_ray if use_ray is None else use_ray


class SweepProgress:
    """The progress of the whole sweep: trials done, running and left, with a time estimate
    (tqdm's, from the rate of finished trials)."""

    def __init__(self, total: int, skipped: int, enabled: bool, desc: str = "sweep") -> None:
        self.enabled = enabled
        self.running: set[str] = set()
        self.left = total - skipped
        self.bar = tqdm(
            total=total,
            initial=skipped,
            unit="trial",
            desc=desc,
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


Runner = Callable[..., Any]
"""``runner(spec, out, threads=..., progress=...)`` runs (or finishes) the trial ``spec`` in
``out`` (``progress``: show its training's progress bar); a module-level function, so that Ray
pickles it by reference."""


def run_sequential(specs: list[dict], out: Path, view: SweepProgress, runner: Runner) -> None:
    """Every trial in this process, one after the other (all torch threads to each), each
    training's progress bar under the sweep's."""
    for spec in specs:
        view.start(spec["id"])
        runner(spec, out, progress=view.enabled)
        view.finish(spec["id"])


_ACTIVE_VIEW: SweepProgress | None = None
"""The progress view of the Ray sweep in flight (see :func:`run_ray`)."""


def _on_trial(event: str, trial: str) -> None:
    if _ACTIVE_VIEW is not None:
        getattr(_ACTIVE_VIEW, event)(trial)


def failure_message(failed: list) -> str:
    """One line for the Ray results ``failed`` (each with ``config``, ``error`` and ``path``):
    which trials failed, the last line of the first one's error and where its traceback is."""
    ids = ", ".join(r.config["spec"]["id"] for r in failed)
    lines = [line.strip() for line in str(failed[0].error).splitlines() if line.strip()]
    cause = lines[-1] if lines else type(failed[0].error).__name__
    return (
        f"{len(failed)} trial(s) failed ({ids}): {cause} (traceback: "
        f"'{Path(failed[0].path) / 'error.txt'}'); run the command again to resume them"
    )


def run_ray(
    specs: list[dict],
    out: Path,
    address: str | None,
    view: SweepProgress,
    runner: Runner,
    parallel: int = 0,
    name: str = "sweep",
) -> None:
    """Every trial as a Ray Tune trial with one CPU (and one torch thread), at most ``parallel``
    at once (0: as many as the cluster's CPUs). With ``address``, the output folder must be on
    storage that every node of the cluster sees."""
    # Trials hold every core, so Tune's driver often waits more than its default half second
    # for a callback, and would warn of it on every step of the progress view.
    os.environ.setdefault("TUNE_WARN_THRESHOLD_S", "60")
    import ray  # noqa: PLC0415 - an optional dependency
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
        runner(config["spec"], Path(config["out"]), threads=1)
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
                name=f"{name}-{int(time.time())}",
                storage_path=str((out / "ray").resolve()),
                verbose=0,
                callbacks=[Progress()],
            ),
            tune_config=tune.TuneConfig(max_concurrent_trials=parallel or None),
        )
        results = tuner.fit()
        failed = [r for r in results if r.error is not None]
        if failed:
            raise TrialsFailedError(failure_message(failed))
    finally:
        _ACTIVE_VIEW = None
        ray.shutdown()

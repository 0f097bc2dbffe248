"""Running a set of resumable trials: one after the other in this process, or as Ray Tune
trials (one CPU and one torch thread each), with one progress bar for the whole set. Used by
``pes reproduce`` and ``pes tune``."""

from __future__ import annotations

import contextlib
import importlib.util
import json
import os
import socket
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from tqdm import tqdm

from pes.errors import ClusterError, ConfigError, TrialsFailedError

RAY_TIMEOUT = 30.0
"""Seconds to wait for a Ray cluster's address to answer (``--ray-timeout``)."""

AUTH_FIX = (
    "set RAY_AUTH_MODE=token and give the cluster's token in RAY_AUTH_TOKEN (or in "
    "~/.ray/auth_token) on this machine"
)


def choose_runner(use_ray: bool | None, ray_address: str | None) -> bool:
    """Whether to run under Ray: ``use_ray`` None means when Ray is installed."""
    have_ray = importlib.util.find_spec("ray") is not None
    if use_ray and not have_ray:
        raise ConfigError("Ray is not installed: pip install 'pes[ray]' (or run with --no-ray)")
    if ray_address and not have_ray:
        raise ConfigError("--ray-address needs Ray: pip install 'pes[ray]'")
    return have_ray if use_ray is None else use_ray


def _host_port(address: str) -> tuple[str, int] | None:
    """``HOST:PORT`` of a GCS address (``ray://`` client addresses and ``auto`` aside)."""
    if "://" in address or address == "auto" or ":" not in address:
        return None
    host, _, port = address.rpartition(":")
    try:
        return host.strip("[]"), int(port)
    except ValueError:
        raise ConfigError(f"--ray-address must be HOST:PORT, got '{address}'") from None


def probe(address: str, timeout: float) -> None:
    """Raise :class:`ClusterError` at once if nothing answers at ``address`` within
    ``timeout`` seconds (Ray itself would retry for minutes)."""
    target = _host_port(address)
    if target is None:
        return
    try:
        socket.create_connection(target, timeout=timeout).close()
    except TimeoutError:
        raise ClusterError(
            f"no Ray cluster answered at {address} within {timeout:g} s (--ray-timeout); "
            "check the address and that the head node runs (ray start --head)"
        ) from None
    except OSError as exc:
        raise ClusterError(
            f"cannot reach a Ray cluster at {address}: {exc.strerror or exc}; check the address "
            "and that the head node runs (ray start --head)"
        ) from None


@contextlib.contextmanager
def quiet_stderr() -> Iterator[list[str]]:
    """Hold what this process (native code included) writes to stderr in the block; yields a
    list that holds it, as one string, once the block ends."""
    sys.stderr.flush()
    saved, text = os.dup(2), []
    with tempfile.TemporaryFile(mode="w+") as held:
        os.dup2(held.fileno(), 2)
        try:
            yield text
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            held.seek(0)
            text.append(held.read())


def connect_ray(address: str | None, timeout: float = RAY_TIMEOUT) -> dict[str, float]:
    """Join the Ray cluster at ``address`` (None: start a local instance) or fail with one line
    (:class:`ClusterError`): nothing answering, a refused authentication, no CPU for a trial.
    Says on stderr which cluster it joined; returns its nodes, CPUs and GPUs."""
    import ray  # noqa: PLC0415 - an optional dependency

    if address:
        probe(address, timeout)
        # Ray tries to join about once a second: as many tries as the timeout's seconds
        os.environ.setdefault("RAY_gcs_server_port_wait_time_s", str(max(1, round(timeout))))
    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")
    with quiet_stderr() as said:  # Ray's own retry warnings, one a second: kept if it joins
        try:
            ray.init(
                # without an address, a local instance of its own: never a cluster that another
                # `ray start` left on this machine
                address=address or "local",
                ignore_reinit_error=True,
                include_dashboard=False,
                log_to_driver=False,
                configure_logging=False,
            )
            error = None
        except (ConnectionError, RuntimeError, ValueError) as exc:
            error = exc
    if error is None:
        sys.stderr.write(said[0])
    else:
        chain, cause = [], error
        while cause is not None and len(chain) < 5:
            chain.append(str(cause))
            cause = cause.__cause__ or cause.__context__
        text = "\n".join(chain) + said[0]
        if any(word in text for word in ("Unauthenticated", "InvalidAuthToken", "auth token")):
            raise ClusterError(
                f"the Ray cluster at {address} refused this connection (it requires token "
                f"authentication): {AUTH_FIX}"
            ) from None
        lines = [line.strip() for line in str(error).splitlines() if line.strip()]
        last = lines[-1] if lines else type(error).__name__
        raise ClusterError(f"cannot join the Ray cluster at {address or 'local'}: {last}") from None
    nodes = [n for n in ray.nodes() if n.get("Alive")]
    resources = ray.cluster_resources()
    found = {
        "nodes": len(nodes),
        "cpus": resources.get("CPU", 0.0),
        "gpus": resources.get("GPU", 0.0),
    }
    where = address or "a local Ray instance"
    print(
        f"ray: joined {where}: {found['nodes']} node(s), {found['cpus']:g} CPUs, "
        f"{found['gpus']:g} GPUs",
        file=sys.stderr,
    )
    if found["cpus"] < 1:
        ray.shutdown()
        raise ClusterError(f"the Ray cluster at {where} has no CPU to run a trial on (1 each)")
    return found


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


def record_attempt(folder: Path, node: str) -> None:
    """Append one line to ``folder/attempts.jsonl`` for a trial attempt starting under Ray: the
    Ray node, host and process that run it, and when it started (a retried trial has several)."""
    folder.mkdir(parents=True, exist_ok=True)
    line = {"node": node, "host": socket.gethostname(), "pid": os.getpid(), "started": time.time()}
    with open(folder / "attempts.jsonl", "a") as f:
        f.write(json.dumps(line) + "\n")


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
    timeout: float = RAY_TIMEOUT,
) -> None:
    """Every trial as a Ray Tune trial with one CPU (and one torch thread), at most ``parallel``
    at once (0: as many as the cluster's CPUs). With ``address`` (joined by
    :func:`connect_ray`, waiting ``timeout`` seconds for it to answer), the output folder must
    be on storage that every node of the cluster sees. A trial that fails (its node lost, its
    process killed) is retried up to twice, resuming from its checkpoints."""
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
        spec, trial_out = config["spec"], Path(config["out"])
        record_attempt(trial_out / "trials" / spec["id"], ray.get_runtime_context().get_node_id())
        runner(spec, trial_out, threads=1)
        tune.report({"finished": 1})

    global _ACTIVE_VIEW
    connect_ray(address, timeout)
    _ACTIVE_VIEW = view
    try:
        tuner = tune.Tuner(
            tune.with_resources(trainable, {"cpu": 1}),
            param_space={"spec": tune.grid_search(specs), "out": str(out.resolve())},
            run_config=tune.RunConfig(
                name=f"{name}-{int(time.time())}",
                storage_path=str((out / "ray").resolve()),
                verbose=0,
                callbacks=[Progress()],
                failure_config=tune.FailureConfig(max_failures=2),
            ),
            tune_config=tune.TuneConfig(max_concurrent_trials=parallel or None),
        )
        # Ray reports cluster events (a node lost) by printing: on stderr, where progress goes,
        # so that stdout holds only the command's own output (``--json``)
        with contextlib.redirect_stdout(sys.stderr):
            results = tuner.fit()
        failed = [r for r in results if r.error is not None]
        if failed:
            raise TrialsFailedError(failure_message(failed))
    finally:
        _ACTIVE_VIEW = None
        ray.shutdown()

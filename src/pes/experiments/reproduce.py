"""``pes reproduce``: run the paper's experiments and write its tables and figures
(docs/reproduce.md).

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

import json
import time
from pathlib import Path
from typing import Any

import yaml

from pes.algos import ALGOS
from pes.errors import ConfigError
from pes.experiments.paper import METHODS
from pes.experiments.report import write_report
from pes.experiments.sweep import (
    RAY_TIMEOUT,
    SweepProgress,
    choose_runner,
    run_ray,
    run_sequential,
)
from pes.experiments.trials import BUDGETS, make_trials, run_trial, train_config
from pes.learn.protocol import PROTOCOLS
from pes.lock import check_free, folder_lock
from pes.sim.config import EnvConfig

TARGETS = ("table4", "table5", "table6", "figures", "all")


def available_methods() -> list[str]:
    """The methods of Table IV (and CBC Net) that this installation can train."""
    return [m for m in METHODS if m == "pid-pf" or m in ALGOS]


def trials_for(
    target: str,
    methods: list[str],
    seeds: int,
    budget: str,
    protocol: str = "pes",
    overrides: dict[str, Any] | None = None,
    scenario: dict[str, Any] | None = None,
) -> list[dict]:
    """The trial specs a target needs, the learners trained under ``protocol`` with
    ``overrides`` (``pes train --set`` keys), every method in ``scenario`` (EnvConfig keys)."""
    if target not in TARGETS:
        raise ConfigError(f"target must be one of {', '.join(TARGETS)}, got '{target}'")
    if target == "table6":
        methods = [m for m in methods if m == "cbc-tp"]
        if not methods:
            raise ConfigError("table6 needs the cbc-tp method")
    elif target == "table5":
        methods = []
    tpnet = target in ("table5", "all")
    return make_trials(methods, seeds, budget, tpnet, protocol, overrides, scenario)


def check_trials(out: Path, specs: list[dict]) -> None:
    """Raise :class:`ConfigError` if a trial in ``out``, finished (``done.json``) or begun
    (``spec.json``, written before its training), was made with another spec (another
    protocol or other ``--set`` keys) than the one asked for now: it would be skipped or
    resumed under the wrong settings. A training trial whose spec differs only in its ``--set``
    keys is the same trial when the configuration it recorded (``run/config.yaml``) is the one
    the spec asked for now resolves to (a ``--set`` that a later preset made its default)."""
    for spec in specs:
        folder = out / "trials" / spec["id"]
        for path in (folder / "spec.json", folder / "done.json"):
            if not path.is_file():
                continue
            record = json.loads(path.read_text())
            made = record.get("spec", record)  # done.json holds its spec, spec.json is one
            if made != spec and not same_training(folder, made, spec):
                raise ConfigError(
                    f"trial {spec['id']} in {out} was made with other settings ({made}, not "
                    f"{spec}); use another --out"
                )


MACHINE_KEYS = ("threads", "cpu_scale")
"""Training keys that say how a machine runs a trial, not what it trains: a trial made with
other values of them is the same trial, and reports do not name them as the folder's settings."""


def same_training(folder: Path, made: dict, spec: dict) -> bool:
    """Whether the training trial in ``folder``, made with spec ``made``, trained with the
    configuration that ``spec`` resolves to now: the specs agree but for their ``set`` keys
    and its recorded ``run/config.yaml`` equals ``spec``'s resolved config (apart from
    :data:`MACHINE_KEYS`)."""
    recorded = folder / "run" / "config.yaml"
    if spec["kind"] != "train" or not recorded.is_file():
        return False
    if {k: v for k, v in made.items() if k != "set"} != {
        k: v for k, v in spec.items() if k != "set"
    }:
        return False
    # through YAML as config.yaml was written, so that both sides hold the same types
    asked = yaml.safe_load(yaml.safe_dump(train_config(spec, BUDGETS[spec["budget"]]).to_dict()))
    trained = yaml.safe_load(recorded.read_text())
    for machine_key in MACHINE_KEYS:
        asked.pop(machine_key, None)
        trained.pop(machine_key, None)
    return asked == trained


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
    protocol: str | None = None,
    outside: str | Path | None = None,
    overrides: dict[str, Any] | None = None,
    scenario: dict[str, Any] | None = None,
    ray_timeout: float = RAY_TIMEOUT,
) -> dict[str, Any]:
    """Run the trials of ``target`` and write its report into ``out``; returns a summary.

    ``protocol``: the training protocol of every learner (:mod:`pes.learn.protocol`; default
    ``paper`` under the paper budget, ``pes`` otherwise).
    ``use_ray``: None uses Ray when it is installed; False runs the trials in this process.
    ``ray_timeout``: seconds to wait for the cluster at ``ray_address`` to answer.
    ``parallel``: at most this many trials at once under Ray (0: one per CPU).
    ``report_only``: run nothing; write the report of the trials finished so far.
    ``outside``: a folder of outside reference runs (``python -m pes.benchmarl.reference``, one
    subfolder each) that Table IV shows as extra columns.
    ``overrides``: settings changed for every learner's training (``pes train --set`` keys,
    e.g. ``{"protocol.n_step": 1}`` to take an aid away); the report names them. A folder holds
    one such choice: trials finished or begun with other settings are an error.
    ``scenario``: :class:`pes.EnvConfig` keys that change the task of every method, in training
    and evaluation alike (e.g. ``{"evader_max_speed": 8.0}``: the positive control of
    results/positive_control); the report names them. Table V takes none.
    """
    if budget not in BUDGETS:
        raise ConfigError(f"budget must be one of {', '.join(BUDGETS)}, got '{budget}'")
    if seeds < 1:
        raise ConfigError(f"seeds must be at least 1, got {seeds}")
    protocol = protocol or ("paper" if budget == "paper" else "pes")
    if protocol not in PROTOCOLS:
        raise ConfigError(f"protocol must be one of {', '.join(PROTOCOLS)}, got '{protocol}'")
    if outside is not None and not Path(outside).is_dir():
        raise ConfigError(f"--outside: no folder '{outside}'")
    use_ray = choose_runner(use_ray, ray_address)
    methods = list(methods) if methods else available_methods()
    scenario = dict(scenario or {})
    if scenario:
        EnvConfig.from_dict(scenario)  # a one-line error for a key or value that is not one
    specs = trials_for(target, methods, seeds, budget, protocol, overrides, scenario)
    out = Path(out)
    check_trials(out, specs)
    out.mkdir(parents=True, exist_ok=True)
    todo = [s for s in specs if not (out / "trials" / s["id"] / "done.json").is_file()]
    finished = len(specs) - len(todo)
    if report_only:
        todo = []
    folders = [out / "trials" / s["id"] for s in todo]
    check_free(folders + [f / "run" for f in folders], "pes reproduce")
    start = time.time()
    view = SweepProgress(len(specs), finished, progress and bool(todo), "reproduce")
    try:
        if todo and use_ray:
            run_ray(todo, out, ray_address, view, run_trial, parallel, "reproduce", ray_timeout)
        elif todo:
            run_sequential(todo, out, view, run_trial)
    finally:
        view.close()
    seconds = time.time() - start
    # The report shows every finished trial of the whole programme in ``out``, not only the
    # methods asked for now, so that a sweep run in parts (``--methods``) keeps one report.
    shown = {k: v for k, v in (overrides or {}).items() if k not in MACHINE_KEYS}
    wanted = {*available_methods(), *methods}
    everything = trials_for(
        target, [m for m in METHODS if m in wanted], seeds, budget, protocol, shown, scenario
    )
    with folder_lock(out, "pes reproduce", wait=True):  # one report writer at a time
        report = write_report(
            out,
            everything,
            target,
            budget,
            seeds,
            command,
            seconds,
            protocol,
            outside,
            shown,
            scenario,
        )
    return {
        "target": target,
        "budget": budget,
        "protocol": protocol,
        "overrides": dict(overrides or {}),
        "scenario": scenario,
        "seeds": seeds,
        "out": str(out),
        # The runner that ran this call's trials; "none" when nothing ran (``--report-only``).
        "runner": ("ray" if use_ray else "sequential") if todo else "none",
        "trials": len(specs),
        "skipped": finished,
        "ran": len(todo),
        "unfinished": len(specs) - finished - len(todo),
        "seconds": round(time.time() - start, 1),
        "files": report,
    }

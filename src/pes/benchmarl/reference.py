"""BenchMARL's algorithms as outside reference runs for Table IV, on PES's training budget.

    python -m pes.benchmarl.reference --algorithm mappo --seed 0 --out results/benchmarl/mappo-s0

One run: BenchMARL's own algorithm, model (MLP) and experiment configs, unchanged except for
the budget, trained on the task ``pes/train`` (the scenario PES's own learners train in under
the ``pes`` protocol), on one torch thread; then its last checkpoint is evaluated with PES's
own protocol (``pes eval``'s: 1000 episodes, disturbance on, crashes disable, the default
evader; the seeds of ``pes reproduce``).

The budget is experience: ``--frames`` (BenchMARL's ``max_n_frames``; a frame is one step of
one environment, as PES's ``env_steps``), by default the quick presets' 2,000,000, the same
work on any machine and beside any job (the runs in results/benchmarl trained 1,000,000). A
checkpoint is written every ``--checkpoint-every`` iterations, so running the same command
again resumes from the last checkpoint (the iterations after it are done again). Writes
``OUT/<experiment>/`` (BenchMARL's folder: CSV logs, checkpoints, ``config.pkl``),
``OUT/cpu.json`` (the CPU time spent, for the record) and ``OUT/result.json`` (the command, the
counters, the evaluation). A run whose policy puts out NaN or infinite actions (its training
diverged) stops there: its last checkpoint, written before, is evaluated, and ``result.json``
says so (``diverged``; ``frames`` is the checkpoint's); one that diverges before its first
checkpoint ends with a one-line error and no ``result.json``.

What BenchMARL gets and PES's learners get alike: the scenario, the training reward, the
disturbance, the env steps and the evaluation. What it does not get: the ``pes`` protocol's
other aids (PID(PF)'s demonstrations, the crash curriculum, the noise schedule, n-step targets,
greedy environments), which are PES's trainer's; a report quoting these runs says so.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import torch
from benchmarl import algorithms
from benchmarl.experiment import Experiment, ExperimentConfig
from benchmarl.experiment.callback import Callback
from benchmarl.models import MlpConfig

from pes.benchmarl import PESTask
from pes.benchmarl.reload import load_benchmarl_policy
from pes.errors import ActionError, CheckpointError, PESError
from pes.evaluate import evaluate
from pes.experiments.budgets import BUDGETS, EVAL_ENVS, EVAL_SEED, eval_config, write_json
from pes.learn.presets import QUICK_RUN
from pes.paths import recorded_command

ALGORITHMS = {"mappo": "Mappo", "ippo": "Ippo", "maddpg": "Maddpg", "masac": "Masac"}
"""``--algorithm`` name -> BenchMARL's config class prefix."""


def quick_frames() -> int:
    """The quick presets' budget of env steps (the same for every PES learner)."""
    return QUICK_RUN["env_steps"]


class CpuClock(Callback):
    """Records in ``record``, after every iteration, the CPU time of this process added to the
    ``spent`` seconds of earlier runs of the experiment, and the frames so far."""

    def __init__(self, spent: float, record: Path) -> None:
        super().__init__()
        self.spent_before, self.record = spent, record
        self.start = time.process_time()

    def on_train_end(self, training_td, group: str) -> None:
        spent = self.spent_before + time.process_time() - self.start
        frames = self.experiment.total_frames
        write_json(self.record, {"cpu_s": round(spent, 1), "frames": frames})


def _latest_checkpoint(out: Path) -> Path | None:
    found = sorted(
        out.glob("*/checkpoints/checkpoint_*.pt"), key=lambda p: int(p.stem.split("_")[-1])
    )
    return found[-1] if found else None


def run_reference(
    algorithm: str,
    seed: int,
    out: str | Path,
    frames: int = 0,
    eval_episodes: int = 1000,
    checkpoint_every: int = 10,
    experiment_overrides: dict[str, Any] | None = None,
    command: str = "",
) -> dict[str, Any]:
    """Train (or finish) one reference run of ``frames`` env steps (0: the quick presets'
    budget) into ``out`` and evaluate it; returns ``result.json`` (see the module docstring).
    ``experiment_overrides``: ``ExperimentConfig`` fields to change (tests shrink the
    batches)."""
    out = Path(out)
    done = out / "result.json"
    if done.is_file():
        return json.loads(done.read_text())
    if algorithm not in ALGORITHMS:
        raise ValueError(f"algorithm must be one of {', '.join(ALGORITHMS)}, got '{algorithm}'")
    frames = frames or quick_frames()
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)
    record = out / "cpu.json"
    resume = _latest_checkpoint(out)
    spent = json.loads(record.read_text())["cpu_s"] if resume and record.is_file() else 0.0

    config = ExperimentConfig.get_from_yaml()
    config.save_folder = str(out)
    config.loggers = ["csv"]
    config.create_json = True
    config.max_n_frames = frames
    config.max_n_iters = None
    config.evaluation = False  # PES evaluates the last checkpoint with its own protocol
    config.checkpoint_at_end = True
    config.sampling_device = config.train_device = "cpu"
    for key, value in (experiment_overrides or {}).items():
        setattr(config, key, value)
    on_policy = algorithm in ("mappo", "ippo")
    config.checkpoint_interval = checkpoint_every * config.collected_frames_per_batch(on_policy)
    config.keep_checkpoints_num = 2
    config.restore_file = str(resume) if resume is not None else None
    reached = int(resume.stem.split("_")[-1]) if resume is not None else 0
    diverged = None
    if reached < frames:
        experiment = Experiment(
            task=PESTask.TRAIN.get_task(),
            algorithm_config=getattr(algorithms, f"{ALGORITHMS[algorithm]}Config").get_from_yaml(),
            model_config=MlpConfig.get_from_yaml(),
            critic_model_config=MlpConfig.get_from_yaml(),
            seed=seed,
            config=config,
            callbacks=[CpuClock(spent, record)],
        )
        try:
            experiment.run()
        except ActionError as exc:  # the simulator refused the policy's actions
            diverged = f"{exc} after {experiment.total_frames:,} frames"
    checkpoint = _latest_checkpoint(out)
    if checkpoint is None:  # only a divergence stops training before checkpoint_at_end
        raise CheckpointError(
            f"{algorithm} seed {seed}: training diverged ({diverged}) before its first "
            f"checkpoint in {out}; nothing to evaluate"
        )
    env_cfg = eval_config(BUDGETS["quick"])
    policy = load_benchmarl_policy(checkpoint, env_cfg)
    result = evaluate(
        policy,
        env_cfg,
        eval_episodes,
        num_envs=min(EVAL_ENVS, eval_episodes),
        seed=EVAL_SEED + 10_000 * seed,
    )
    clock = json.loads(record.read_text()) if record.is_file() else {}
    summary = {
        "method": f"{algorithm.upper()} (BenchMARL)",
        "algorithm": algorithm,
        "seed": seed,
        "task": "pes/train",
        "frame_budget": frames,
        "command": command,
        "checkpoint": str(checkpoint.relative_to(out)),
        "frames": int(checkpoint.stem.split("_")[-1]),
        "cpu_s": clock.get("cpu_s"),
        "eval": result.summary(),
    }
    if diverged is not None:
        summary["diverged"] = diverged
    write_json(done, summary)
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m pes.benchmarl.reference", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--algorithm", required=True, choices=list(ALGORITHMS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--frames", type=int, default=0, help="env steps (default: the quick presets' 2,000,000)"
    )
    parser.add_argument("--eval-episodes", type=int, default=1000)
    parser.add_argument("--checkpoint-every", type=int, default=10, help="iterations")
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    command = recorded_command(["python", "-m", "pes.benchmarl.reference", *(argv or sys.argv[1:])])
    try:
        summary = run_reference(
            args.algorithm,
            args.seed,
            args.out,
            frames=args.frames,
            eval_episodes=args.eval_episodes,
            checkpoint_every=args.checkpoint_every,
            command=command,
        )
    except PESError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    # Through the importable module: BenchMARL pickles the callbacks (CpuClock) into the run's
    # config.pkl, which must name pes.benchmarl.reference, not __main__, for another process
    # (pes eval) to load the run's checkpoints.
    from pes.benchmarl import reference

    sys.exit(reference.main())

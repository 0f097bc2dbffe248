"""The training loop every learner shares: batched collection, the training protocol's
environment aids (training reward, disturbance, crash and speed curricula), updates, logging,
checkpoints and resumption. Off-policy learners update ``update_credit()`` times per vector step
once ``ready()``; on-policy ones (PPO) are ``ready()`` when their rollout is full, and each
``update()`` consumes it.

A run lives in one folder::

    OUT/config.yaml      the resolved TrainConfig (its protocol and learner sections included)
    OUT/progress.csv     one row per ``log_every`` episodes (success rate, average reward,
                         episode steps, losses, TP Net FDE/ADE, env-steps/s, updates/s, ...)
    OUT/tb/              the same as TensorBoard scalars
    OUT/checkpoint.pt    the latest checkpoint (written atomically)
    OUT/policy.pt        the trained policy (at the end)
    OUT/best_policy.pt   the policy at the log row with the best training score so far
                         (pursuers: highest success rate, then fewest steps; the evader:
                         the lowest pursuer success rate, then the most steps)
    OUT/summary.json     counters, the aids the protocol applied, the evaluation of policy.pt
    OUT/init_from.json   with ``init_from``: the checkpoint or policy file the networks started
                         from, which networks it gave and its counters

``train(cfg, out, Learner, resume=True)`` continues from ``checkpoint.pt`` exactly as the run
would have gone on: networks, optimisers, replay buffer, noise, RNG states, counters, the
environments' episodes in flight and the log row being gathered come back; ``progress.csv`` and
TensorBoard are cut back to the checkpoint's last row, and ``best_policy.pt`` to the
checkpoint's. SIGINT and SIGTERM
stop a run at the next step with a checkpoint, ``policy.pt`` and ``summary.json`` written.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
import yaml
from tqdm import tqdm

from pes.errors import CheckpointError, ConfigError, TrainingInterruptedError
from pes.evaluate import evaluate
from pes.learn.checkpoint import (
    CHECKPOINT_FORMAT,
    POLICY_FORMAT,
    VERSION,
    load_file,
    load_modules,
    remove_stale_temporaries,
    resolve_policy_path,
    save_atomic,
    save_policy_file,
    write_text_atomic,
)
from pes.learn.config import TrainConfig
from pes.learn.learner import Learner
from pes.lock import folder_lock
from pes.sim.bench import machine_info
from pes.sim.env import make_env, resolve_device
from pes.strict import to_dict

LOG_COLUMNS = (
    "episodes",
    "env_steps",
    "updates",
    "wall_s",
    "cpu_s",
    "success_rate",
    "avg_reward",
    "episode_steps",
    "crashes",
    "noise",
    "critic_loss",
    "actor_loss",
    "q_mean",
    "tp_loss",
    "tp_fde",
    "tp_ade",
    "entropy",
    "approx_kl",
    "clip_frac",
    "alpha",
    "env_steps_per_s",
    "updates_per_s",
    "evader_speed",
    "crashes_disable",
    "demonstrating",
    "bc_share",
)
"""Columns of ``progress.csv`` (docs/training.md, "The run folder"); ``wall_s`` and ``cpu_s``
are the run's wall and process CPU seconds so far (CPU: every thread's); ``avg_reward`` is each
episode's total (team-mean) training reward divided by its steps, averaged over the row's
episodes; ``evader_speed`` the evader's speed cap (m/s) during the row's episodes;
``crashes_disable`` 1 when they were played with crashes that disable (the protocol's crash
curriculum); ``demonstrating`` 1 when the demonstrator played (part of) the row; ``bc_share``
the share of actor samples that are demonstrations (the protocol's ``bc_weight``)."""

# Changing these between a run and its resumption is allowed; anything else is a mismatch.
RESUMABLE_CHANGES = {
    "episodes",
    "time_limit",
    "cpu_limit",
    "cpu_scale",
    "env_steps",
    "checkpoint_every",
    "eval_episodes",
    "device",
    "threads",
    "compile_env",
    "tensorboard",
    "init_from",
}


@dataclass
class Progress:
    episodes: int = 0
    env_steps: int = 0
    updates: int = 0
    wall_s: float = 0.0
    cpu_s: float = 0.0  # this run's process CPU time (all threads), s
    update_credit: float = 0.0
    best_score: float = -math.inf
    log_rows: int = 0  # rows of progress.csv written
    evader_speed: float = 0.0  # the speed curriculum's current cap (m/s); 0 = no curriculum
    crashes_disable: bool = False  # the crash curriculum has switched
    cpus: list[str] = field(default_factory=list)  # CPU models the run trained on, in order


class RunLogger:
    """CSV (and TensorBoard, when installed) logs of a run. On resume the logs are cut back to
    the first ``rows`` rows (those of the checkpoint), so that rows written after it and lost
    with the run are written once."""

    def __init__(self, out: Path, tensorboard: bool, resume: bool, rows: int, episodes: int):
        self.path = out / "progress.csv"
        columns: tuple[str, ...] = LOG_COLUMNS
        kept: list[list[str]] = []
        if resume and self.path.is_file() and self.path.stat().st_size > 0:
            with open(self.path, newline="") as f:
                lines = list(csv.reader(f))
            columns, kept = tuple(lines[0]), lines[1 : 1 + rows]
        with open(self.path, "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(columns)
            writer.writerows(kept)
        if not resume:  # a fresh run in a used folder (its checkpoint lost): its logs anew
            for stale in (out / "tb").glob("events.out.tfevents.*"):
                stale.unlink()
        self.file = open(self.path, "a", newline="")  # noqa: SIM115 - closed in close()
        self.writer = csv.DictWriter(self.file, fieldnames=columns, extrasaction="ignore")
        self.tb = None
        if tensorboard:
            try:
                from torch.utils.tensorboard import SummaryWriter  # noqa: PLC0415 - optional

                # events after the checkpoint's last row are dropped
                purge = episodes + 1 if resume else None
                self.tb = SummaryWriter(str(out / "tb"), purge_step=purge)
            except ImportError:
                self.tb = None

    def write(self, row: dict[str, float]) -> None:
        self.writer.writerow({k: row.get(k, "") for k in self.writer.fieldnames})
        self.file.flush()
        if self.tb is not None:
            for k, v in row.items():
                if k != "episodes" and isinstance(v, (int, float)) and math.isfinite(v):
                    self.tb.add_scalar(k, v, row["episodes"])
            self.tb.flush()

    def close(self) -> None:
        self.file.close()
        if self.tb is not None:
            self.tb.close()


class StopSignals:
    """SIGINT and SIGTERM ask the run to stop at its next step (a second one stops it at once)."""

    def __init__(self) -> None:
        self.requested = False
        self.previous: dict[int, Any] = {}

    def __enter__(self) -> StopSignals:
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(ValueError):  # not the main thread: no handlers
                self.previous[sig] = signal.signal(sig, self.handle)
        return self

    def handle(self, signum, frame) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def __exit__(self, *exc) -> None:
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)


def _check_resumable(saved: dict[str, Any], cfg: TrainConfig, path: Path) -> None:
    now = to_dict(cfg)
    diff = sorted(k for k in now if k not in RESUMABLE_CHANGES and saved.get(k) != now[k])
    if diff:
        raise CheckpointError(
            f"'{path}' was trained with different settings ({', '.join(diff)}); resume with "
            "the same configuration or start a new --out folder"
        )


def train(
    cfg: TrainConfig,
    out: str | Path,
    learner_cls: type[Learner],
    resume: bool = False,
    progress: bool = True,
) -> dict[str, Any]:
    """Train ``learner_cls`` (the method ``cfg.algo``) into the folder ``out``, holding its lock
    (:mod:`pes.lock`: a second writer fails at once); returns a summary (and writes it to
    ``out/summary.json``)."""
    with folder_lock(out, "pes train"):
        return Trainer(cfg, Path(out), learner_cls, resume, progress).run()


class Trainer:
    """One training run in its folder. The constructor sets it up (a fresh start, or everything
    a checkpoint holds); :meth:`run` is the loop, one vector step at a time: :meth:`collect`,
    :meth:`update`, a log row when one is due (:meth:`log_row`, then :meth:`keep_best` and
    :meth:`curricula`), a checkpoint when one is due, until a budget or a signal stops it;
    then :meth:`finish` writes the checkpoint, ``policy.pt`` and ``summary.json``."""

    def __init__(
        self, cfg: TrainConfig, out: Path, learner_cls: type[Learner], resume: bool, progress: bool
    ) -> None:
        self.cfg, self.out, self.learner_cls, self.progress = cfg, out, learner_cls, progress
        self.ckpt_path = out / "checkpoint.pt"
        if resume and not self.ckpt_path.is_file():
            raise CheckpointError(f"nothing to resume: no checkpoint at '{self.ckpt_path}'")
        if not resume and self.ckpt_path.exists():
            raise ConfigError(
                f"'{out}' already holds a run; pass --resume to continue it or choose another --out"
            )
        out.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(out)
        if cfg.threads:
            torch.set_num_threads(cfg.threads)
        self.device = resolve_device(cfg.device)
        self.protocol = cfg.protocol
        torch.manual_seed(cfg.seed)
        self.env_cfg = learner_cls.adapt_env(cfg.env_config())
        self.learner = learner_cls(cfg, self.env_cfg, self.device)
        self.gen = torch.Generator().manual_seed(cfg.seed)
        self.prog = Progress()
        self.best_state: dict[str, Any] | None = None
        ckpt = self._restore() if resume else self._start()
        self.aids = learner_cls.aids(self.protocol)
        write_text_atomic(out / "config.yaml", yaml.safe_dump(to_dict(cfg), sort_keys=False))

        self.env, self.obs, self.info = self.start_env()
        self.top_speed = self.env_cfg.evader_max_speed
        self.logger = RunLogger(
            out, cfg.tensorboard, resume, self.prog.log_rows, self.prog.episodes
        )
        self.window: dict[str, list] = {"success": [], "steps": [], "reward": [], "crashes": []}
        self.demo_in_row = False  # whether the demonstrator played (part of) this log row
        self.stats_sum: dict[str, float] = {}
        self.stats_count: dict[str, int] = {}
        self.reward_sum = torch.zeros(cfg.num_envs, device=self.device)
        self.next_row = (self.prog.episodes // cfg.log_every + 1) * cfg.log_every
        if ckpt is not None:
            self._restore_live(ckpt)
        self._start_clocks()

    # --- setup ----------------------------------------------------------------------------------
    def _start(self) -> None:
        """A fresh run: the networks of ``init_from`` (recorded), the curricula's first stage."""
        cfg, prog, protocol = self.cfg, self.prog, self.protocol
        if cfg.init_from:  # record which checkpoint it was: the source run may go on
            source = init_networks(self.learner, cfg)
            write_text_atomic(self.out / "init_from.json", json.dumps(source, indent=2) + "\n")
        if protocol.speed_curriculum is not None:
            prog.evader_speed = protocol.speed_curriculum.start
        if protocol.crash_curriculum is not None and protocol.crash_curriculum.disable_at == 0:
            prog.crashes_disable = True

    def _restore(self) -> dict[str, Any]:
        """Networks, optimisers, buffer, counters and best policy from the checkpoint; what the
        lost stretch after it wrote goes (its snapshots, its best policy). Returns it."""
        cfg, learner, out = self.cfg, self.learner, self.out
        ckpt = load_file(self.ckpt_path, CHECKPOINT_FORMAT)
        _check_resumable(ckpt["train_config"], cfg, self.ckpt_path)
        load_modules(learner.modules(), ckpt["modules"], str(self.ckpt_path))
        for name, opt in learner.optimizers().items():
            opt.load_state_dict(ckpt["optimizers"][name])
        if "buffer" in ckpt:
            learner.buffer.load_state_dict(ckpt["buffer"])
        self.prog = prog = Progress(**ckpt["progress"])
        if "cpus" not in ckpt["progress"] and prog.env_steps:  # older than the record
            prog.cpus = ["unrecorded CPU"]
        learner.updates = prog.updates
        self.best_state = ckpt.get("best_policy")
        for snap in (out / "snapshots").glob("ep*.pt"):
            if int(snap.stem[2:]) > prog.episodes:
                snap.unlink()
        if self.best_state is not None:
            save_atomic(self.best_state, out / "best_policy.pt")
        else:
            (out / "best_policy.pt").unlink(missing_ok=True)
        return ckpt

    def _restore_live(self, ckpt: dict[str, Any]) -> None:
        """The episodes in flight, the log row being gathered and the RNG states: the run goes
        on where its checkpoint was written."""
        live, device = ckpt["live"], self.device
        self.env.set_state(live["env"])
        self.obs = live["obs"].to(device)
        self.info = {k: v.to(device) for k, v in live["info"].items()}
        self.reward_sum = live["reward_sum"].to(device)
        self.window, self.demo_in_row = live["window"], live["demo_in_row"]
        self.stats_sum, self.stats_count = live["stats_sum"], live["stats_count"]
        self.next_row = live["next_row"]
        self.learner.load_state_dict(ckpt["learner"])
        torch.set_rng_state(ckpt["rng"]["torch"])
        self.gen.set_state(ckpt["rng"]["sampler"])

    def _start_clocks(self) -> None:
        """Wall and CPU clocks, limits and the progress bar, from this part of the run on."""
        cfg, prog = self.cfg, self.prog
        self.start = time.perf_counter()
        self.wall0, self.cpu0, self.cpu_start = prog.wall_s, prog.cpu_s, time.process_time()
        if (cpu := machine_info()["cpu"]) not in prog.cpus:
            prog.cpus.append(cpu)
        self.last_ckpt = self.start
        self.row_start = (self.start, prog.env_steps, prog.updates)
        self.deadline = cfg.time_limit * 60.0 if cfg.time_limit > 0 else math.inf
        self.cpu_deadline = cfg.cpu_limit * 60.0 * cfg.cpu_scale if cfg.cpu_limit > 0 else math.inf
        # The bar counts what the budget counts: env steps under an env_steps budget, else
        # episodes.
        self.by_steps = cfg.env_steps > 0
        total, done_so_far = (
            (cfg.env_steps, prog.env_steps) if self.by_steps else (cfg.episodes, prog.episodes)
        )
        unit = "env steps" if self.by_steps else "ep"
        self.total = total
        self.bar = tqdm(
            total=total,
            initial=min(done_so_far, total),
            unit_scale=self.by_steps,
            desc=f"train {cfg.algo} ({self.protocol.name})",
            disable=not self.progress,
            dynamic_ncols=True,
            # tqdm's own estimate counts one budget only: "left" below knows the other limits.
            bar_format="{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} "
            + unit
            + " [{elapsed}{postfix}]",
        )
        self.first_episode, self.first_steps = prog.episodes, prog.env_steps
        self.row: dict[str, float] | None = None  # the latest log row
        self.shown = -math.inf  # when the bar's figures were last refreshed

    def start_env(self):
        """The training environments, every episode fresh: at a start, seeded by the episodes
        already played, and when the crash rule switches."""
        cfg, prog = self.cfg, self.prog
        crash_mode = "disable" if prog.crashes_disable else self.env_cfg.crash_mode
        env = make_env(
            self.env_cfg.replace(crash_mode=crash_mode),
            num_envs=cfg.num_envs,
            device=self.device,
            seed=cfg.seed * 1_000_003 + prog.episodes,
            compile=cfg.compile_env,
            wait_kernels=True,  # every step of a run on the same path
        )
        if prog.evader_speed > 0:
            env.set_evader_max_speed(prog.evader_speed)
        obs, info = env.reset()
        self.learner.episode_reset(torch.ones(cfg.num_envs, dtype=torch.bool, device=self.device))
        return env, obs, info

    # --- the loop -------------------------------------------------------------------------------
    def run(self) -> dict[str, Any]:
        """Train until a budget or a signal stops the run; returns its summary (evaluated when
        ``eval_episodes``)."""
        cfg, prog = self.cfg, self.prog
        stopped_by = "episodes"
        with StopSignals() as signals:
            try:
                while prog.episodes < cfg.episodes:
                    self.collect()
                    self.update()
                    now = time.perf_counter()
                    prog.wall_s = self.wall0 + now - self.start
                    prog.cpu_s = self.cpu0 + time.process_time() - self.cpu_start
                    if prog.episodes >= self.next_row and self.window["success"]:
                        row = self.log_row(now)
                        self.keep_best(row)
                        self.curricula(row)
                        self._next_row(now)
                    if (
                        cfg.checkpoint_every > 0
                        and now - self.last_ckpt >= cfg.checkpoint_every * 60
                    ):
                        self.checkpoint()
                        self.last_ckpt = time.perf_counter()
                    reason = self.stop_reason(signals.requested)
                    if reason:
                        stopped_by = reason
                        break
            finally:
                self.bar.close()
                self.logger.close()
            summary = self.finish(stopped_by)
        if cfg.eval_episodes > 0:
            summary["eval"] = evaluate_run(
                self.learner_cls, self.out / "policy.pt", cfg, cfg.eval_episodes, self.progress
            )
            write_text_atomic(self.out / "summary.json", json.dumps(summary, indent=2) + "\n")
        return summary

    def collect(self) -> None:
        """One vector step: act, step the environments, record; the finished episodes counted."""
        cfg, prog, learner, window = self.cfg, self.prog, self.learner, self.window
        scale = self.noise_scale = self.protocol.noise.scale(prog.episodes)
        self.demo_in_row |= learner.demonstrating()
        actions, evader_actions = learner.act(self.obs, self.info, scale, self.gen)
        alive = self.info["obs_mask"][:, :, 0].float()
        obs2, reward, terminated, truncated, info2 = self.env.step(actions, evader_actions)
        learner.record(self.info, actions, evader_actions, reward, terminated, info2)
        self.reward_sum += (reward * alive).sum(-1) / alive.sum(-1).clamp(min=1.0)
        prog.env_steps += cfg.num_envs
        if self.by_steps:
            self.bar.update(min(cfg.num_envs, max(0, self.total - self.bar.n)))  # stop at total
        done = terminated | truncated
        if bool(done.any()):
            idx = torch.nonzero(done).flatten()
            steps = info2["steps"][idx].float()
            window["success"] += info2["success"][idx].tolist()
            window["steps"] += steps.tolist()
            window["reward"] += (self.reward_sum[idx] / steps).tolist()
            window["crashes"] += info2["crashes"][idx].tolist()
            self.reward_sum[idx] = 0.0
            learner.episode_reset(done)
            prog.episodes += len(idx)
            if not self.by_steps:
                self.bar.update(len(idx))
            if self.progress and time.perf_counter() - self.shown >= 1.0:
                self.show(time.perf_counter())
        self.obs, self.info = obs2, info2

    def update(self) -> None:
        """The updates this step earned, their metrics gathered for the log row."""
        learner, prog = self.learner, self.prog
        if not learner.ready():
            return
        prog.update_credit += learner.update_credit()
        while prog.update_credit >= 1.0:
            for k, v in learner.update(self.gen).items():
                self.stats_sum[k] = self.stats_sum.get(k, 0.0) + v
                self.stats_count[k] = self.stats_count.get(k, 0) + 1
            prog.updates += 1
            prog.update_credit -= 1.0

    def log_row(self, now: float) -> dict[str, float]:
        """Write the log row of the episodes since the last one (and a snapshot); returns it."""
        prog, window = self.prog, self.window
        dt = max(now - self.row_start[0], 1e-9)
        row = {
            "episodes": prog.episodes,
            "env_steps": prog.env_steps,
            "updates": prog.updates,
            "wall_s": round(prog.wall_s, 1),
            "cpu_s": round(prog.cpu_s, 1),
            "success_rate": sum(window["success"]) / len(window["success"]),
            "avg_reward": sum(window["reward"]) / len(window["reward"]),
            "episode_steps": sum(window["steps"]) / len(window["steps"]),
            "crashes": sum(window["crashes"]) / len(window["crashes"]),
            "noise": self.noise_scale,  # the exploration scale of the row's last step
            "env_steps_per_s": (prog.env_steps - self.row_start[1]) / dt,
            "updates_per_s": (prog.updates - self.row_start[2]) / dt,
            "evader_speed": self.env.evader_max_speed,
            "crashes_disable": int(prog.crashes_disable),
            "demonstrating": int(self.demo_in_row),
        }
        row.update({k: v / self.stats_count[k] for k, v in self.stats_sum.items()})
        self.logger.write(row)
        prog.log_rows += 1
        if self.cfg.snapshots:
            (self.out / "snapshots").mkdir(exist_ok=True)
            self.save_policy(self.out / "snapshots" / f"ep{prog.episodes:06d}.pt", self.meta())
        self.row = row
        return row

    def keep_best(self, row: dict[str, float]) -> None:
        """``best_policy.pt`` follows the row with the best training score. Ties go to the later
        row: a run that never captures keeps its latest policy, not its first, barely trained
        one. A row that the demonstrator played (partly) measures the demonstrator, not the
        learner: it does not count."""
        score = self.learner.score(row["success_rate"], row["episode_steps"])
        if score >= self.prog.best_score and not self.demo_in_row:
            self.prog.best_score = score
            self.best_state = self.save_policy(
                self.out / "best_policy.pt", {**self.meta(), "best_at": self.prog.episodes}
            )

    def curricula(self, row: dict[str, float]) -> None:
        """The protocol's curricula after a log row (never on a row the demonstrator played):
        a faster evader, or crashes that disable from now on; the best policy is then sought
        afresh (success rates under other rules do not compare)."""
        prog, speed, crash = (
            self.prog,
            self.protocol.speed_curriculum,
            self.protocol.crash_curriculum,
        )
        if self.demo_in_row:
            return
        if (
            speed is not None
            and prog.evader_speed < self.top_speed
            and row["success_rate"] >= speed.success
        ):  # harder from the next step on
            prog.evader_speed = min(self.top_speed, prog.evader_speed + speed.step)
            self.env.set_evader_max_speed(prog.evader_speed)
            prog.best_score = -math.inf
        if (
            crash is not None
            and not prog.crashes_disable
            and crash.disable_at <= row["success_rate"]
        ):  # the episodes in flight are abandoned, as at a resume
            prog.crashes_disable = True
            self.learner.on_restart()
            self.env, self.obs, self.info = self.start_env()
            self.reward_sum.zero_()
            prog.best_score = -math.inf

    def _next_row(self, now: float) -> None:
        """Start gathering the next log row."""
        self.window = {k: [] for k in self.window}
        self.demo_in_row = False
        self.stats_sum, self.stats_count = {}, {}
        self.row_start = (now, self.prog.env_steps, self.prog.updates)
        self.next_row = (self.prog.episodes // self.cfg.log_every + 1) * self.cfg.log_every

    def stop_reason(self, interrupted: bool) -> str | None:
        """Why the run stops now (a limit reached, a signal), or None."""
        cfg, prog = self.cfg, self.prog
        if prog.wall_s >= self.deadline:
            return "time_limit"
        if prog.cpu_s >= self.cpu_deadline:
            return "cpu_limit"
        if cfg.env_steps and prog.env_steps >= cfg.env_steps:
            return "env_steps"
        return "interrupted" if interrupted else None

    # --- what a run writes ----------------------------------------------------------------------
    def finish(self, stopped_by: str) -> dict[str, Any]:
        """The checkpoint, ``policy.pt`` and ``summary.json`` at the end (an interrupted run
        raises :class:`TrainingInterruptedError` after writing them); returns the summary."""
        self.checkpoint()
        final = {**self.meta(), "stopped_by": stopped_by}
        self.save_policy(self.out / "policy.pt", final)
        summary: dict[str, Any] = {
            "algo": self.cfg.algo,
            "protocol": self.protocol.name,
            "aids": self.aids,
            "out": str(self.out),
            **final,
        }
        write_text_atomic(self.out / "summary.json", json.dumps(summary, indent=2) + "\n")
        if stopped_by == "interrupted":
            raise TrainingInterruptedError(
                f"interrupted after {self.prog.episodes} episodes; checkpoint written, continue "
                f"with --resume --out {self.out}"
            )
        return summary

    def checkpoint(self) -> None:
        """Everything the run needs to go on exactly as it would have, written atomically."""
        cfg, learner = self.cfg, self.learner
        payload = {
            "format": CHECKPOINT_FORMAT,
            "version": VERSION,
            "algo": cfg.algo,
            "train_config": to_dict(cfg),
            "env_config": to_dict(self.env_cfg),
            "modules": {k: m.state_dict() for k, m in learner.modules().items()},
            "optimizers": {k: o.state_dict() for k, o in learner.optimizers().items()},
            "learner": learner.state_dict(),
            "rng": {"torch": torch.get_rng_state(), "sampler": self.gen.get_state()},
            "progress": vars(self.prog).copy(),
            "torch": str(torch.__version__),
        }
        if self.best_state is not None:
            payload["best_policy"] = self.best_state
        if cfg.checkpoint_buffer and hasattr(learner, "buffer"):
            payload["buffer"] = learner.buffer.state_dict()
        # the episodes in flight and the log row being gathered, so that a resumed run goes
        # on exactly as the run would have
        payload["live"] = {
            "env": {k: v.cpu() for k, v in self.env.get_state().items()},
            "obs": self.obs.cpu(),
            "info": {k: v.cpu() for k, v in self.info.items()},
            "reward_sum": self.reward_sum.cpu(),
            "window": self.window,
            "demo_in_row": self.demo_in_row,
            "stats_sum": self.stats_sum,
            "stats_count": self.stats_count,
            "next_row": self.next_row,
        }
        save_atomic(payload, self.ckpt_path)

    def meta(self) -> dict[str, Any]:
        """The run's counters, as policy files and the summary record them."""
        prog = self.prog
        return {
            "episodes": prog.episodes,
            "env_steps": prog.env_steps,
            "updates": prog.updates,
            "wall_s": round(prog.wall_s, 1),
            "cpu_s": round(prog.cpu_s, 1),
            "cpu_scale": self.cfg.cpu_scale,  # cpu_s / cpu_scale: minutes of the reference CPU
            "seed": self.cfg.seed,
            "torch": str(torch.__version__),
            "torch_threads": torch.get_num_threads(),  # at the end of the run (or this part)
            "cpus": list(prog.cpus),
            "crashes_disable": prog.crashes_disable,  # the crash rule it ended under
        }

    def save_policy(self, path: Path, info: dict[str, Any]) -> dict[str, Any]:
        policy = {k: m.state_dict() for k, m in self.learner.policy_modules().items()}
        cfg = self.cfg
        return save_policy_file(path, cfg.algo, to_dict(cfg), to_dict(self.env_cfg), policy, info)

    def show(self, now: float) -> None:
        """The bar's figures: success, steps and reward of the episodes finished since the
        last log row (else that row's), and the time left by the episodes or the time limit."""
        cfg, prog, window, row = self.cfg, self.prog, self.window, self.row
        recent = window if window["success"] else None
        if recent is None and row is None:
            return

        def mean(key: str) -> float:
            return sum(recent[key]) / len(recent[key])

        figures = {
            "success": mean("success") if recent else row["success_rate"],
            "steps": mean("steps") if recent else row["episode_steps"],
            "reward": mean("reward") if recent else row["avg_reward"],
        }
        run_s = now - self.start
        done_here = prog.episodes - self.first_episode
        left = min(self.deadline - prog.wall_s, self.cpu_deadline - prog.cpu_s)
        if done_here > 0:
            left = min(left, (cfg.episodes - prog.episodes) * run_s / done_here)
        steps_here = prog.env_steps - self.first_steps
        if cfg.env_steps and steps_here > 0:
            left = min(left, (cfg.env_steps - prog.env_steps) * run_s / steps_here)
        shown_figures = {
            "success": f"{figures['success']:.2f}",
            "steps": f"{figures['steps']:.0f}",
            "reward": f"{figures['reward']:.3f}",
        }
        if prog.evader_speed:
            shown_figures["evader"] = f"{prog.evader_speed:g}m/s"
        shown_figures["left"] = tqdm.format_interval(max(left, 0.0)) if math.isfinite(left) else "?"
        self.bar.set_postfix(shown_figures)  # a dict keeps this order (keywords would be sorted)
        self.shown = now


def init_networks(learner: Learner, cfg: TrainConfig) -> dict[str, Any]:
    """Load the networks of ``learner`` from ``cfg.init_from``: a run folder or its
    ``checkpoint.pt`` (every network, target networks included), or a policy file or shipped
    model name (``cbc-tp``: the acting networks and their target copies; the critic starts
    fresh). Returns the source's path, what was loaded and its counters (episodes, env steps,
    updates, wall time)."""
    path = Path(cfg.init_from)
    path = path / "checkpoint.pt" if path.is_dir() else resolve_policy_path(cfg.init_from)
    source = load_file(path, (CHECKPOINT_FORMAT, POLICY_FORMAT))
    algo = source.get("algo")
    if algo != cfg.algo:
        raise CheckpointError(f"init_from: '{path}' holds a {algo} run, this run trains {cfg.algo}")
    modules = learner.modules()
    if source["format"] == CHECKPOINT_FORMAT:
        load_modules(modules, source["modules"], str(path))
        loaded, progress = "all", source["progress"]
    else:
        acting = learner.policy_modules()
        load_modules(acting, source["policy"], str(path))
        for name, module in acting.items():  # target copies start equal to their networks
            if f"{name}_target" in modules:
                modules[f"{name}_target"].load_state_dict(module.state_dict())
        loaded = sorted(n for n in modules if n.removesuffix("_target") in acting)
        progress = source["meta"]
    return {"path": str(path.resolve()), "loaded": loaded, "progress": progress}


def evaluate_run(
    learner_cls: type[Learner], policy_path: Path, cfg: TrainConfig, episodes: int, progress: bool
) -> dict:
    """Evaluate a trained policy under the paper's protocol (its reward, disturbance on,
    crashes disable): pursuers against the training evader; an evader against its training
    opponent."""
    env_cfg = cfg.env_config().for_evaluation()
    state = load_file(policy_path, POLICY_FORMAT)["policy"]
    if learner_cls.pursuer:
        policy, modules = learner_cls.build_policy(cfg, env_cfg, cfg.device)
        opponent = env_cfg.evader_policy
    else:
        env_cfg = env_cfg.replace(evader_policy="ddpg", evader_model=str(policy_path))
        policy, modules = learner_cls.build_policy(cfg, env_cfg, cfg.device)
        opponent = cfg.learner.opponent
    load_modules(modules, state, str(policy_path))
    for module in modules.values():
        module.eval()
    result = evaluate(
        policy,
        env_cfg,
        episodes=episodes,
        num_envs=min(episodes, 100),
        seed=10_000 + cfg.seed,
        device=cfg.device,
        progress=progress,
    )
    return {"opponent": opponent, **result.summary()}

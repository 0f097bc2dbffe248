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

from pes.config import to_dict
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
"""Columns of ``progress.csv``; ``wall_s`` and ``cpu_s`` are the run's wall and process CPU
seconds so far (CPU: every thread's); ``avg_reward`` is each episode's total (team-mean) training
reward divided by its steps, averaged over the row's episodes (SPEC §4); ``evader_speed`` the
evader's speed cap (m/s) during the row's episodes; ``crashes_disable`` 1 when they were played
with crashes that disable (the protocol's crash curriculum); ``demonstrating`` 1 when the
demonstrator played (part of) the row; ``bc_share`` the share of actor samples that are
demonstrations (the protocol's ``bc_weight``)."""

# Changing these between a run and its resumption is allowed; anything else is a mismatch.
RESUMABLE_CHANGES = {
    "episodes",
    "time_limit",
    "cpu_limit",
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
        return _train(cfg, Path(out), learner_cls, resume, progress)


def _train(
    cfg: TrainConfig, out: Path, learner_cls: type[Learner], resume: bool, progress: bool
) -> dict[str, Any]:
    ckpt_path = out / "checkpoint.pt"
    if resume and not ckpt_path.is_file():
        raise CheckpointError(f"nothing to resume: no checkpoint at '{ckpt_path}'")
    if not resume and ckpt_path.exists():
        raise ConfigError(
            f"'{out}' already holds a run; pass --resume to continue it or choose another --out"
        )
    out.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(out)
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    device = resolve_device(cfg.device)
    protocol = cfg.protocol

    torch.manual_seed(cfg.seed)
    env_cfg = learner_cls.adapt_env(cfg.env_config())
    learner = learner_cls(cfg, env_cfg, device)
    gen = torch.Generator().manual_seed(cfg.seed)
    prog = Progress()
    best_state: dict[str, Any] | None = None
    if resume:
        ckpt = load_file(ckpt_path, CHECKPOINT_FORMAT)
        _check_resumable(ckpt["train_config"], cfg, ckpt_path)
        load_modules(learner.modules(), ckpt["modules"], str(ckpt_path))
        for name, opt in learner.optimizers().items():
            opt.load_state_dict(ckpt["optimizers"][name])
        if "buffer" in ckpt:
            learner.buffer.load_state_dict(ckpt["buffer"])
        prog = Progress(**ckpt["progress"])
        if "cpus" not in ckpt["progress"] and prog.env_steps:  # a checkpoint older than the record
            prog.cpus = ["unrecorded CPU"]
        learner.updates = prog.updates
        best_state = ckpt.get("best_policy")
        # what the lost stretch after the checkpoint wrote goes: its snapshots, its best policy
        for snap in (out / "snapshots").glob("ep*.pt"):
            if int(snap.stem[2:]) > prog.episodes:
                snap.unlink()
        if best_state is not None:
            save_atomic(best_state, out / "best_policy.pt")
        else:
            (out / "best_policy.pt").unlink(missing_ok=True)
    else:
        if cfg.init_from:  # record which checkpoint it was: the source run may go on
            source = init_networks(learner, cfg)
            write_text_atomic(out / "init_from.json", json.dumps(source, indent=2) + "\n")
        if protocol.speed_curriculum is not None:
            prog.evader_speed = protocol.speed_curriculum.start
        if protocol.crash_curriculum is not None and protocol.crash_curriculum.disable_at == 0:
            prog.crashes_disable = True
    aids = learner_cls.aids(protocol)
    write_text_atomic(out / "config.yaml", yaml.safe_dump(to_dict(cfg), sort_keys=False))

    def checkpoint() -> None:
        payload = {
            "format": CHECKPOINT_FORMAT,
            "version": VERSION,
            "algo": cfg.algo,
            "train_config": to_dict(cfg),
            "env_config": to_dict(env_cfg),
            "modules": {k: m.state_dict() for k, m in learner.modules().items()},
            "optimizers": {k: o.state_dict() for k, o in learner.optimizers().items()},
            "learner": learner.state_dict(),
            "rng": {"torch": torch.get_rng_state(), "sampler": gen.get_state()},
            "progress": vars(prog).copy(),
            "torch": str(torch.__version__),
        }
        if best_state is not None:
            payload["best_policy"] = best_state
        if cfg.checkpoint_buffer and hasattr(learner, "buffer"):
            payload["buffer"] = learner.buffer.state_dict()
        # the episodes in flight and the log row being gathered, so that a resumed run goes
        # on exactly as the run would have
        payload["live"] = {
            "env": {k: v.cpu() for k, v in env.get_state().items()},
            "obs": obs.cpu(),
            "info": {k: v.cpu() for k, v in info.items()},
            "reward_sum": reward_sum.cpu(),
            "window": window,
            "demo_in_row": demo_in_row,
            "stats_sum": stats_sum,
            "stats_count": stats_count,
            "next_row": next_row,
        }
        save_atomic(payload, ckpt_path)

    def meta() -> dict[str, Any]:
        return {
            "episodes": prog.episodes,
            "env_steps": prog.env_steps,
            "updates": prog.updates,
            "wall_s": round(prog.wall_s, 1),
            "cpu_s": round(prog.cpu_s, 1),
            "seed": cfg.seed,
            "torch": str(torch.__version__),
            "torch_threads": torch.get_num_threads(),  # at the end of the run (or this part)
            "cpus": list(prog.cpus),
            "crashes_disable": prog.crashes_disable,  # the crash rule it ended under
        }

    def save_policy(path: Path, info: dict[str, Any]) -> dict[str, Any]:
        policy = {k: m.state_dict() for k, m in learner.policy_modules().items()}
        return save_policy_file(path, cfg.algo, to_dict(cfg), to_dict(env_cfg), policy, info)

    def start_env():
        """The training environments, every episode fresh: at a start, seeded by the episodes
        already played, and when the crash rule switches."""
        crash_mode = "disable" if prog.crashes_disable else env_cfg.crash_mode
        env = make_env(
            env_cfg.replace(crash_mode=crash_mode),
            num_envs=cfg.num_envs,
            device=device,
            seed=cfg.seed * 1_000_003 + prog.episodes,
            compile=cfg.compile_env,
            wait_kernels=True,  # every step of a run on the same path
        )
        if prog.evader_speed > 0:
            env.set_evader_max_speed(prog.evader_speed)
        obs, info = env.reset()
        learner.episode_reset(torch.ones(cfg.num_envs, dtype=torch.bool, device=device))
        return env, obs, info

    env, obs, info = start_env()
    top_speed = env_cfg.evader_max_speed
    logger = RunLogger(out, cfg.tensorboard, resume, prog.log_rows, prog.episodes)
    window: dict[str, list] = {"success": [], "steps": [], "reward": [], "crashes": []}
    demo_in_row = False  # whether the demonstrator played (part of) this log row
    stats_sum: dict[str, float] = {}
    stats_count: dict[str, int] = {}
    reward_sum = torch.zeros(cfg.num_envs, device=device)
    next_row = (prog.episodes // cfg.log_every + 1) * cfg.log_every
    if resume:  # the run goes on where its checkpoint was written
        live = ckpt["live"]
        env.set_state(live["env"])
        obs = live["obs"].to(device)
        info = {k: v.to(device) for k, v in live["info"].items()}
        reward_sum = live["reward_sum"].to(device)
        window, demo_in_row = live["window"], live["demo_in_row"]
        stats_sum, stats_count = live["stats_sum"], live["stats_count"]
        next_row = live["next_row"]
        learner.load_state_dict(ckpt["learner"])
        torch.set_rng_state(ckpt["rng"]["torch"])
        gen.set_state(ckpt["rng"]["sampler"])
    start = time.perf_counter()
    wall0, cpu0, cpu_start = prog.wall_s, prog.cpu_s, time.process_time()
    if (cpu := machine_info()["cpu"]) not in prog.cpus:
        prog.cpus.append(cpu)
    last_ckpt = start
    row_start = (start, prog.env_steps, prog.updates)
    deadline = cfg.time_limit * 60.0 if cfg.time_limit > 0 else math.inf
    cpu_deadline = cfg.cpu_limit * 60.0 if cfg.cpu_limit > 0 else math.inf
    # The bar counts what the budget counts: env steps under an env_steps budget, else episodes.
    by_steps = cfg.env_steps > 0
    total, done_so_far = (
        (cfg.env_steps, prog.env_steps) if by_steps else (cfg.episodes, prog.episodes)
    )
    unit = "env steps" if by_steps else "ep"
    bar = tqdm(
        total=total,
        initial=min(done_so_far, total),
        unit_scale=by_steps,
        desc=f"train {cfg.algo} ({protocol.name})",
        disable=not progress,
        dynamic_ncols=True,
        # tqdm's own estimate counts one budget only: "left" below also knows the other limits.
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} "
        + unit
        + " [{elapsed}{postfix}]",
    )
    first_episode, first_steps = prog.episodes, prog.env_steps
    row: dict[str, float] | None = None  # the latest log row
    shown = -math.inf  # when the bar's figures were last refreshed

    def show(now: float) -> None:
        """The bar's figures: success, steps and reward of the episodes finished since the
        last log row (else that row's), and the time left by the episodes or the time limit."""
        nonlocal shown
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
        run_s = now - start
        done_here = prog.episodes - first_episode
        left = min(deadline - prog.wall_s, cpu_deadline - prog.cpu_s)
        if done_here > 0:
            left = min(left, (cfg.episodes - prog.episodes) * run_s / done_here)
        steps_here = prog.env_steps - first_steps
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
        bar.set_postfix(shown_figures)  # a dict keeps this order (keywords would be sorted)
        shown = now

    stopped_by = "episodes"
    with StopSignals() as signals:
        try:
            while prog.episodes < cfg.episodes:
                scale = protocol.noise.scale(prog.episodes)
                demo_in_row |= learner.demonstrating()
                actions, evader_actions = learner.act(obs, info, scale, gen)
                alive = info["obs_mask"][:, :, 0].float()
                obs2, reward, terminated, truncated, info2 = env.step(actions, evader_actions)
                learner.record(info, actions, evader_actions, reward, terminated, info2)
                reward_sum += (reward * alive).sum(-1) / alive.sum(-1).clamp(min=1.0)
                prog.env_steps += cfg.num_envs
                if by_steps:
                    bar.update(min(cfg.num_envs, max(0, total - bar.n)))  # stop at the total
                done = terminated | truncated
                if bool(done.any()):
                    idx = torch.nonzero(done).flatten()
                    steps = info2["steps"][idx].float()
                    window["success"] += info2["success"][idx].tolist()
                    window["steps"] += steps.tolist()
                    window["reward"] += (reward_sum[idx] / steps).tolist()
                    window["crashes"] += info2["crashes"][idx].tolist()
                    reward_sum[idx] = 0.0
                    learner.episode_reset(done)
                    prog.episodes += len(idx)
                    if not by_steps:
                        bar.update(len(idx))
                    if progress and time.perf_counter() - shown >= 1.0:
                        show(time.perf_counter())
                obs, info = obs2, info2

                if learner.ready():
                    prog.update_credit += learner.update_credit()
                    while prog.update_credit >= 1.0:
                        for k, v in learner.update(gen).items():
                            stats_sum[k] = stats_sum.get(k, 0.0) + v
                            stats_count[k] = stats_count.get(k, 0) + 1
                        prog.updates += 1
                        prog.update_credit -= 1.0

                now = time.perf_counter()
                prog.wall_s = wall0 + now - start
                prog.cpu_s = cpu0 + time.process_time() - cpu_start
                if prog.episodes >= next_row and window["success"]:
                    dt = max(now - row_start[0], 1e-9)
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
                        "noise": scale,
                        "env_steps_per_s": (prog.env_steps - row_start[1]) / dt,
                        "updates_per_s": (prog.updates - row_start[2]) / dt,
                        "evader_speed": env.evader_max_speed,
                        "crashes_disable": int(prog.crashes_disable),
                        "demonstrating": int(demo_in_row),
                    }
                    row.update({k: v / stats_count[k] for k, v in stats_sum.items()})
                    logger.write(row)
                    prog.log_rows += 1
                    if cfg.snapshots:
                        (out / "snapshots").mkdir(exist_ok=True)
                        save_policy(out / "snapshots" / f"ep{prog.episodes:06d}.pt", meta())
                    score = learner.score(row["success_rate"], row["episode_steps"])
                    # Ties go to the later row: a run that never captures keeps its latest
                    # policy, not its first, barely trained one. A row that the demonstrator
                    # played (partly) measures the demonstrator, not the learner: it neither
                    # counts for best_policy.pt nor advances a curriculum.
                    if score >= prog.best_score and not demo_in_row:
                        prog.best_score = score
                        best_state = save_policy(
                            out / "best_policy.pt", {**meta(), "best_at": prog.episodes}
                        )
                    speed = protocol.speed_curriculum
                    if (
                        speed is not None
                        and prog.evader_speed < top_speed
                        and not demo_in_row
                        and row["success_rate"] >= speed.success
                    ):
                        # Harder from the next step on; the best policy is then sought afresh
                        # at the new speed (success rates at different speeds do not compare).
                        prog.evader_speed = min(top_speed, prog.evader_speed + speed.step)
                        env.set_evader_max_speed(prog.evader_speed)
                        prog.best_score = -math.inf
                    crash = protocol.crash_curriculum
                    if (
                        crash is not None
                        and crash.disable_at <= row["success_rate"]
                        and not prog.crashes_disable
                        and not demo_in_row
                    ):
                        # Crashes disable from now on: the episodes in flight are abandoned (as
                        # at a resume) and the best policy is sought afresh under the new rule.
                        prog.crashes_disable = True
                        learner.on_restart()
                        env, obs, info = start_env()
                        reward_sum.zero_()
                        prog.best_score = -math.inf
                    window = {k: [] for k in window}
                    demo_in_row = False
                    stats_sum, stats_count = {}, {}
                    row_start = (now, prog.env_steps, prog.updates)
                    next_row = (prog.episodes // cfg.log_every + 1) * cfg.log_every
                if cfg.checkpoint_every > 0 and now - last_ckpt >= cfg.checkpoint_every * 60.0:
                    checkpoint()
                    last_ckpt = time.perf_counter()
                if prog.wall_s >= deadline:
                    stopped_by = "time_limit"
                    break
                if prog.cpu_s >= cpu_deadline:
                    stopped_by = "cpu_limit"
                    break
                if cfg.env_steps and prog.env_steps >= cfg.env_steps:
                    stopped_by = "env_steps"
                    break
                if signals.requested:
                    stopped_by = "interrupted"
                    break
        finally:
            bar.close()
            logger.close()
        checkpoint()
        final = {**meta(), "stopped_by": stopped_by}
        save_policy(out / "policy.pt", final)
        summary: dict[str, Any] = {
            "algo": cfg.algo,
            "protocol": protocol.name,
            "aids": aids,
            "out": str(out),
            **final,
        }
        write_text_atomic(out / "summary.json", json.dumps(summary, indent=2) + "\n")
        if stopped_by == "interrupted":
            raise TrainingInterruptedError(
                f"interrupted after {prog.episodes} episodes; checkpoint written, continue with "
                f"--resume --out {out}"
            )
    if cfg.eval_episodes > 0:
        summary["eval"] = evaluate_run(
            learner_cls, out / "policy.pt", cfg, cfg.eval_episodes, progress
        )
        write_text_atomic(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    return summary


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

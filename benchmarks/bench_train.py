"""Training throughput of the learners: where a training step's time goes.

    python benchmarks/bench_train.py                 # CPU: benchmarks/results/train_cpu.json
    python benchmarks/bench_train.py --device cuda --out benchmarks/results/train_cuda.json

For each algorithm (default: every learner) and preset (default: quick) it measures, after a
warm-up that fills the replay buffer (or one rollout):

* ``collect_env_steps_per_s``: acting (TP Net + actor on every pursuer, exploration), the
  simulator step and storing the transitions, with no gradient updates;
* ``update_ms``: one update (a replay learner's gradient step of every network; an on-policy
  learner's epochs over a whole rollout), and its part ``tp_update_ms``, TP Net's supervised
  step;
* ``train_env_steps_per_s``: what a run achieves at the preset's update ratio
  (``updates_per_env_step``: 1 / ``update_every`` for the replay learners, 1 / the rollout's
  transitions for the on-policy ones): 1 / (1 / collect + updates_per_env_step * update_s);
* ``bytes_per_transition`` of the replay buffer and what 1e6 transitions take;
* ``update_time_by_op``: the share of an update's time taken by its five costliest operators.

With ``--baseline REF`` each measurement runs twice in turn, in fresh processes: once on the
code of git revision REF (checked out into a temporary worktree) and once on this tree, so that
both see the same machine and the same load, ``--repeats`` times (default 3); the output
gains the baseline's rows and, per learner, ``speedup``: the ratios of the medians of the
training env-steps/s and of the update times.

    python benchmarks/bench_train.py --threads 1 --baseline c14c6ee \
        --out benchmarks/results/train_cpu_speedup.json
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import torch

from pes.algos import ALGOS, build_train_config
from pes.sim.bench import machine_info
from pes.sim.env import make_env, resolve_device


def learner_and_env(algo: str, preset: str, device: str, compile_env: bool = True):
    """``algo``'s ``preset`` as a benchmark runs it: its config, learner class, learner and
    environments (seed 0), and the sampler's generator. The learner acts and updates on its own:
    without the demonstrations, the quick preset's PID(PF) (its first 100,000 transitions)
    would play through a timed window."""
    cfg = build_train_config(algo, preset, {"device": device, "protocol.demonstrations": None})
    cls = ALGOS[algo]
    env_cfg = cls.adapt_env(cfg.env_config())
    torch.manual_seed(0)
    learner = cls(cfg, env_cfg, torch.device(device))
    env = make_env(
        env_cfg,
        num_envs=cfg.num_envs,
        device=device,
        seed=0,
        compile=compile_env,
        wait_kernels=True,
    )
    return cfg, cls, env_cfg, learner, env, torch.Generator().manual_seed(0)


def measure(algo: str, preset: str, device: str, seconds: float) -> dict:
    cfg, cls, env_cfg, learner, env, gen = learner_and_env(algo, preset, device)
    obs, info = env.reset()
    sync = torch.cuda.synchronize if device == "cuda" else (lambda: None)
    lc = cfg.learner

    def step() -> None:
        nonlocal obs, info
        actions, evader = learner.act(obs, info, 0.2, gen)
        obs2, reward, terminated, truncated, info2 = env.step(actions, evader)
        learner.record(info, actions, evader, reward, terminated, info2)
        obs, info = obs2, info2

    def collect(steps: int) -> None:
        """``steps`` vector steps; an on-policy rollout that fills is dropped, not learnt."""
        for _ in range(steps):
            step()
            if cls.on_policy and learner.ready():
                learner.buffer.clear()

    def fill() -> None:
        """An on-policy learner's next rollout (a replay learner's buffer stays filled)."""
        while cls.on_policy and not learner.ready():
            step()

    if cls.on_policy:
        updates_per_step = 1.0 / lc.rollout_steps
        need = lc.rollout_steps
    else:
        updates_per_step = learner.update_credit()
        need = max(lc.warmup, lc.batch_size, getattr(lc, "tp_batch_size", 0)) // cfg.num_envs
    # Fill the buffer past the warm-up and play past the first episode end, so that the step
    # and the auto-reset pass are both compiled before the timed window.
    collect(max(need + 20, env_cfg.max_steps + 5))
    sync()
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        collect(20)
        steps += 20
    sync()
    collect_rate = steps * cfg.num_envs / (time.perf_counter() - start)

    for _ in range(3):
        fill()
        learner.update(gen)
    updates, busy, tp_time = 0, 0.0, 0.0
    while busy < seconds:
        fill()
        if hasattr(learner, "tp"):
            t0 = time.perf_counter()
            learner.auxiliary_update(gen)
            sync()
            tp_time += time.perf_counter() - t0
        t0 = time.perf_counter()
        learner.update(gen)
        sync()
        busy += time.perf_counter() - t0
        updates += 1
    profile = profile_update(learner, gen, device, fill)
    update_s = busy / updates  # update() includes its one TP step
    tp_s = tp_time / updates
    # a vector step's time in training: collecting it, and its share of an update
    train_rate = cfg.num_envs / (cfg.num_envs / collect_rate + updates_per_step * update_s)
    per = getattr(learner.buffer, "bytes_per_transition", None)
    return {
        "algo": algo,
        "preset": preset,
        "device": device,
        "num_envs": cfg.num_envs,
        "num_pursuers": env_cfg.num_pursuers,
        "hidden": getattr(lc, "hidden", None),
        "batch_size": lc.batch_size,
        "update_every": getattr(lc, "update_every", None),
        "rollout_steps": getattr(lc, "rollout_steps", None),
        "updates_per_env_step": round(updates_per_step / cfg.num_envs, 6),
        "env_compiled": env.compiled,
        "collect_env_steps_per_s": round(collect_rate, 1),
        "update_ms": round(update_s * 1000, 2),
        "tp_update_ms": round(tp_s * 1000, 2) if tp_time else None,
        "updates_per_s": round(1.0 / update_s, 2),
        "train_env_steps_per_s": round(train_rate, 1),
        "update_share_of_time": round(1 - train_rate / collect_rate, 3),
        "bytes_per_transition": per,
        "buffer_gb_at_1e6": round(per * 1e6 / 1e9, 3) if per else None,
        "update_time_by_op": profile,
    }


def profile_update(learner, gen: torch.Generator, device: str, fill, updates: int = 10) -> dict:
    """Where an update's time goes: the share of the self time of the five costliest operator
    kinds over ``updates`` updates (torch.profiler), summed forward and backward; ``fill()``
    collects what each update needs, outside the profile."""
    from torch.profiler import ProfilerActivity, profile

    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device == "cuda" else [])
    key = "self_device_time_total" if device == "cuda" else "self_cpu_time_total"
    totals: Counter[str] = Counter()
    for _ in range(updates):
        fill()
        with profile(activities=activities) as prof:
            learner.update(gen)
        for e in prof.key_averages():
            totals[e.key] += getattr(e, key, 0)
    total = sum(totals.values())
    return {k: round(v / total, 3) for k, v in totals.most_common(5)}


def measure_in(src: Path, algo: str, preset: str, args: argparse.Namespace) -> dict:
    """:func:`measure` in a fresh process that imports ``pes`` from ``src``."""
    cmd = [sys.executable, __file__, "--row", algo, preset, "--device", args.device]
    cmd += ["--seconds", str(args.seconds), "--threads", str(args.threads)]
    env = dict(os.environ, PYTHONPATH=str(src))
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"bench_train: {algo} {preset} failed under {src}: {done.stderr.strip()[-500:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def worktree(ref: str, into: str) -> Path:
    """The ``src`` folder of git revision ``ref`` checked out under ``into``."""
    root = Path(__file__).resolve().parents[1]
    path = Path(into) / "baseline"
    done = subprocess.run(
        ["git", "-C", str(root), "worktree", "add", "--detach", str(path), ref],
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        sys.exit(f"bench_train: cannot check out {ref}: {done.stderr.strip()}")
    return path / "src"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--algos", nargs="+", default=list(ALGOS), choices=list(ALGOS))
    parser.add_argument(
        "--presets", nargs="+", default=["quick"], choices=["quick", "gpu", "paper", "tiny"]
    )
    parser.add_argument("--seconds", type=float, default=10.0, help="per measurement")
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument(
        "--baseline", default=None, help="a git revision to measure beside this tree, in turn"
    )
    parser.add_argument(
        "--repeats", type=int, default=3, help="with --baseline: measurements of each, in turn"
    )
    parser.add_argument("--row", nargs=2, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    resolve_device(args.device)  # a clear error for a device this machine lacks
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.row:  # one measurement for a parent run with --baseline
        print(json.dumps(measure(*args.row, args.device, args.seconds)), flush=True)
        return
    out = Path(args.out or f"benchmarks/results/train_{args.device}.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    result = {
        "machine": machine_info(args.device),
        "results": [],
        "command": "python benchmarks/bench_train.py "
        + " ".join(
            f"--{k.replace('_', '-')} {' '.join(v) if isinstance(v, list) else v}"
            for k, v in vars(args).items()
            if v is not None and k not in ("out", "row")
        ),
    }
    with tempfile.TemporaryDirectory() as tmp:
        base = worktree(args.baseline, tmp) if args.baseline else None
        here = Path(__file__).resolve().parents[1] / "src"
        try:
            for algo in args.algos:
                for preset in args.presets:
                    if base is None:
                        rows = [measure(algo, preset, args.device, args.seconds)]
                    else:  # in turn, so that both see the same load
                        rows, olds, news = [], [], []
                        for _ in range(args.repeats):
                            olds.append(measure_in(base, algo, preset, args))
                            news.append(measure_in(here, algo, preset, args))
                            rows += [olds[-1] | {"code": args.baseline}]
                            rows += [news[-1] | {"code": "this tree"}]
                        result.setdefault("speedup", []).append(speedup(olds, news))
                        print(json.dumps(result["speedup"][-1]), flush=True)
                    for row in rows:
                        print(json.dumps(row), flush=True)
                    result["results"] += rows
                    # written after every row, so that a run stopped early keeps what it measured
                    out.write_text(json.dumps(result, indent=2) + "\n")
        finally:
            if base is not None:
                subprocess.run(["git", "worktree", "remove", "--force", str(base.parent)])


def speedup(old: list[dict], new: list[dict]) -> dict:
    """How much faster ``new`` trains than ``old`` (measurements of each, taken in turn): the
    ratios of their medians of training and collecting env-steps/s and of update time."""

    def median(rows: list[dict], key: str) -> float:
        return statistics.median(row[key] for row in rows)

    return {
        "algo": new[0]["algo"],
        "preset": new[0]["preset"],
        "repeats": len(new),
        "train_env_steps_per_s": round(
            median(new, "train_env_steps_per_s") / median(old, "train_env_steps_per_s"), 3
        ),
        "collect_env_steps_per_s": round(
            median(new, "collect_env_steps_per_s") / median(old, "collect_env_steps_per_s"), 3
        ),
        "update_time": round(median(old, "update_ms") / median(new, "update_ms"), 3),
        "baseline_train_env_steps_per_s": median(old, "train_env_steps_per_s"),
        "train_env_steps_per_s_now": median(new, "train_env_steps_per_s"),
    }


if __name__ == "__main__":
    main()

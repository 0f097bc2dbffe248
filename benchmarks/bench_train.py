"""Training throughput of the learners: where a training step's time goes.

    python benchmarks/bench_train.py                 # CPU: benchmarks/results/train_cpu.json
    python benchmarks/bench_train.py --device cuda --out benchmarks/results/train_cuda.json

For each algorithm and preset it measures, after a warm-up that fills the replay buffer:

* ``collect_env_steps_per_s``: acting (TP Net + actor on every pursuer, OU noise), the fused
  simulator step and storing the transitions, with no gradient updates;
* ``update_ms``: one gradient update, and its parts (``tp_update_ms``, TP Net's supervised step;
  the rest is the critic, the actor and the soft target updates);
* ``train_env_steps_per_s``: what a run achieves with the preset's ``update_every``
  (one update per that many transitions): 1 / (1 / collect + update_s / update_every);
* ``bytes_per_transition`` of the replay buffer and what 1e6 transitions take;
* ``update_time_by_op``: the share of an update's time taken by its five costliest operators.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch

from pes.algos import ALGOS, build_train_config
from pes.sim.bench import machine_info
from pes.sim.env import make_env, resolve_device


def measure(algo: str, preset: str, device: str, seconds: float) -> dict:
    # The learner's own acting and updates: without this, the quick preset's PID(PF)
    # demonstrations (its first 100,000 transitions) would play through the timed window.
    cfg = build_train_config(algo, preset, {"device": device, "protocol.demonstrations": None})
    env_cfg = ALGOS[algo].adapt_env(cfg.env_config())
    torch.manual_seed(0)
    learner = ALGOS[algo](cfg, env_cfg, torch.device(device))
    env = make_env(env_cfg, num_envs=cfg.num_envs, device=device, seed=0, compile=True)
    gen = torch.Generator().manual_seed(0)
    obs, info = env.reset()
    sync = torch.cuda.synchronize if device == "cuda" else (lambda: None)

    def collect(steps: int) -> None:
        nonlocal obs, info
        for _ in range(steps):
            actions, evader = learner.act(obs, info, 0.2, gen)
            obs2, reward, terminated, truncated, info2 = env.step(actions, evader)
            learner.record(info, actions, evader, reward, terminated, info2)
            obs, info = obs2, info2

    lc = cfg.learner
    need = max(lc.warmup, lc.batch_size, getattr(lc, "tp_batch_size", 0)) // cfg.num_envs + 20
    # Fill the buffer past the warm-up and play past the first episode end, so that the step
    # and the auto-reset pass are both compiled before the timed window.
    collect(max(need, env_cfg.max_steps + 5))
    sync()
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        collect(20)
        steps += 20
    sync()
    collect_rate = steps * cfg.num_envs / (time.perf_counter() - start)

    for _ in range(3):
        learner.update(gen)
    updates, tp_time, start = 0, 0.0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        if hasattr(learner, "tp"):
            t0 = time.perf_counter()
            learner.auxiliary_update(gen)
            sync()
            tp_time += time.perf_counter() - t0
        learner.update(gen)
        updates += 1
    sync()
    total = time.perf_counter() - start
    profile = profile_update(learner, gen, device)
    # update() includes one TP step: subtract the extra one timed separately
    update_s = (total - tp_time) / updates
    tp_s = tp_time / updates
    train_rate = 1.0 / (1.0 / collect_rate + update_s / lc.update_every)
    per = learner.buffer.bytes_per_transition
    return {
        "algo": algo,
        "preset": preset,
        "device": device,
        "num_envs": cfg.num_envs,
        "num_pursuers": env_cfg.num_pursuers,
        "hidden": lc.hidden,
        "batch_size": lc.batch_size,
        "update_every": lc.update_every,
        "env_compiled": env.compiled,
        "collect_env_steps_per_s": round(collect_rate, 1),
        "update_ms": round(update_s * 1000, 2),
        "tp_update_ms": round(tp_s * 1000, 2) if tp_time else None,
        "updates_per_s": round(1.0 / update_s, 2),
        "train_env_steps_per_s": round(train_rate, 1),
        "update_share_of_time": round(1 - train_rate / collect_rate, 3),
        "bytes_per_transition": per,
        "buffer_gb_at_1e6": round(per * 1e6 / 1e9, 3),
        "update_time_by_op": profile,
    }


def profile_update(learner, gen: torch.Generator, device: str, updates: int = 10) -> dict:
    """Where an update's time goes: the share of the self time of the five costliest operator
    kinds over ``updates`` updates (torch.profiler), summed forward and backward."""
    from torch.profiler import ProfilerActivity, profile

    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device == "cuda" else [])
    with profile(activities=activities) as prof:
        for _ in range(updates):
            learner.update(gen)
    key = "self_device_time_total" if device == "cuda" else "self_cpu_time_total"
    events = [e for e in prof.key_averages() if getattr(e, key, 0) > 0]
    total = sum(getattr(e, key) for e in events)
    top = sorted(events, key=lambda e: getattr(e, key), reverse=True)[:5]
    return {e.key: round(getattr(e, key) / total, 3) for e in top}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--algos", nargs="+", default=["cbc-tp", "cbc", "evader-ddpg"])
    parser.add_argument("--presets", nargs="+", default=["quick", "paper"])
    parser.add_argument("--seconds", type=float, default=10.0, help="per measurement")
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    resolve_device(args.device)  # a clear error for a device this machine lacks
    if args.threads:
        torch.set_num_threads(args.threads)
    out = Path(args.out or f"benchmarks/results/train_{args.device}.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    result = {
        "machine": machine_info(args.device),
        "results": [],
        "command": "python benchmarks/bench_train.py "
        + " ".join(
            f"--{k.replace('_', '-')} {' '.join(v) if isinstance(v, list) else v}"
            for k, v in vars(args).items()
            if v is not None and k != "out"
        ),
    }
    for algo in args.algos:
        for preset in args.presets:
            row = measure(algo, preset, args.device, args.seconds)
            print(json.dumps(row), flush=True)
            result["results"].append(row)
            # written after every row, so that a run stopped early keeps what it measured
            out.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()

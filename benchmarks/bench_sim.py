"""Simulator throughput, side by side with VMAS and MPE2, in one run on one machine.

    python benchmarks/bench_sim.py     # CPU: writes benchmarks/results/sim_cpu.json
    python benchmarks/bench_sim.py --beside-busy --out benchmarks/results/sim_cpu_busy.json
    python benchmarks/bench_sim.py --device cuda --sizes 4096 65536 262144 \
        --skip-baselines --out benchmarks/results/sim_cuda.json

What is measured (env-steps per second; one env-step = one control step of one game):

* PES batched (``pes.make_env``), full quadrotor model (10 physics sub-steps of eqs. (1)-(2)
  under the attitude PID), 5 pursuers with random actions and the scripted ``flee`` evader,
  episodes desynchronised so that auto-resets happen at their steady rate: as a user gets it
  (``pes_default``: the compiled CPU kernels of ``pes.sim.kernels`` with a few eager torch
  operations around them) and, with ``--compiled``, fused by ``torch.compile`` as well.
* VMAS ``simple_tag`` with 5 chasers, 1 runner and 8 landmarks, continuous actions, random
  actions, the same batch sizes.
* The single-environment PettingZoo path: ``pes.pettingzoo.parallel_env()`` (its defaults)
  against MPE2 ``simple_tag_v3`` (5 adversaries, 1 good agent, 8 obstacles, continuous
  actions), both stepped with actions sampled from their action spaces.

The machine this runs on is shared and its speed drifts by a factor of two over minutes, so
the simulators being compared are timed in interleaved chunks (PES, VMAS, PES, VMAS, ...) and
each figure is the median of its chunks. VMAS and MPE2 are optional (``pip install vmas
mpe2``); missing ones are reported as such.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import torch

import pes
from pes.experiments.budgets import write_json
from pes.sim.bench import Timer, machine_info, pes_timer

ROUNDS = 5


def vmas_timer(num_envs: int, device: str) -> Timer:
    import vmas

    env = vmas.make_env(
        "simple_tag",
        num_envs=num_envs,
        device=device,
        continuous_actions=True,
        num_good_agents=1,
        num_adversaries=5,
        num_landmarks=8,
        seed=0,
    )
    env.reset()
    generator = torch.Generator().manual_seed(0)
    pool = [
        [(torch.rand(num_envs, 2, generator=generator) * 2 - 1).to(device) for _ in env.agents]
        for _ in range(8)
    ]
    counter = [0]

    def step() -> None:
        env.step(pool[counter[0] % 8])
        counter[0] += 1

    for _ in range(5):
        step()
    return Timer(step, num_envs)


def mpe2_timer() -> Timer:
    from mpe2 import simple_tag_v3

    env = simple_tag_v3.parallel_env(
        num_good=1, num_adversaries=5, num_obstacles=8, max_cycles=10**9, continuous_actions=True
    )
    env.reset(seed=0)
    for agent in env.agents:
        env.action_space(agent).seed(0)

    def step() -> None:
        env.step({a: env.action_space(a).sample() for a in env.agents})

    for _ in range(10):
        step()
    return Timer(step, 1)


def pettingzoo_timer(compile: bool = False) -> tuple[Timer, float]:
    from pes.pettingzoo import parallel_env
    from pes.sim import kernels

    kernels.wait()  # the steady speed: no background compilation during the timed window

    env = parallel_env(compile=compile)
    env.reset(seed=0)
    for agent in env.possible_agents:
        env.action_space(agent).seed(0)

    def step() -> None:
        if not env.agents:
            env.reset()
        env.step({a: env.action_space(a).sample() for a in env.agents})

    start = time.perf_counter()
    for _ in range(520):  # past the first episode's end: the reset path is compiled too
        step()
    return Timer(step, 1), round(time.perf_counter() - start, 1)


def chunk_calls(num_envs: int, steps: int) -> int:
    return max(4, steps // ROUNDS) if num_envs >= 1024 else max(20, steps // ROUNDS)


def log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 64, 1024, 4096])
    parser.add_argument("--steps", type=int, default=200, help="timed steps per measurement")
    parser.add_argument("--skip-baselines", action="store_true", help="PES only")
    parser.add_argument(
        "--compiled", action="store_true", help="also the step fused by torch.compile"
    )
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default: 1)")
    parser.add_argument(
        "--beside-busy",
        action="store_true",
        help="measure beside a second CPU-bound process (a Python busy loop), as contention",
    )
    parser.add_argument("--out", default="benchmarks/results/sim_cpu.json")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    busy = None
    if args.beside_busy:
        busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        return measure(args)
    finally:
        if busy is not None:
            busy.kill()


def measure(args: argparse.Namespace) -> int:

    config = pes.EnvConfig().validate()
    report: dict = {
        "benchmark": "simulator throughput (env-steps/s), medians of interleaved chunks",
        "command": " ".join(["python"] + sys.argv),
        "date": time.strftime("%Y-%m-%d"),
        "device": args.device,
        "machine": machine_info(args.device),
        "load_average_before": round(os.getloadavg()[0], 2),
        "beside_busy_process": args.beside_busy,
        "scenario": "default EnvConfig: 5 pursuers (random actions), flee evader, quadrotor "
        "dynamics with 10 sub-steps, 8 buildings",
        "sizes": [],
    }
    for size in args.sizes:
        row: dict = {"num_envs": size}
        timers = {}
        log(f"{size} envs: warming up")
        timers["pes_default"], row["pes_default_setup"] = pes_timer(
            config, size, args.device, compile=False
        )
        if args.compiled:
            timers["pes_compiled"], row["pes_compiled_setup"] = pes_timer(config, size, args.device)
        if not args.skip_baselines:
            try:
                timers["vmas_simple_tag"] = vmas_timer(size, args.device)
            except ImportError as exc:
                row["vmas_simple_tag"] = f"not installed ({exc})"
        calls = chunk_calls(size, args.steps)
        for _ in range(ROUNDS):
            for timer in timers.values():
                timer.chunk(calls)
        for name, timer in timers.items():
            row[name] = round(timer.median, 1)
            row[f"{name}_chunks"] = [round(r, 1) for r in timer.rates]
        if "vmas_simple_tag" in timers:
            for name in ("pes_default", "pes_compiled"):
                if name in timers:
                    ratio = row[name] / row["vmas_simple_tag"]
                    row[f"{name}_over_vmas"] = round(ratio, 2)
        log(json.dumps({k: v for k, v in row.items() if not k.endswith("chunks")}))
        report["sizes"].append(row)
        save(report, args.out)

    if not args.skip_baselines:
        single: dict = {}
        log("PettingZoo, 1 environment")
        pz, single["pes_pettingzoo_warmup_s"] = pettingzoo_timer()
        timers = {"pes_pettingzoo": pz}
        if args.compiled:
            timers["pes_pettingzoo_compiled"], single["compiled_warmup_s"] = pettingzoo_timer(True)
        try:
            timers["mpe2_simple_tag"] = mpe2_timer()
        except ImportError as exc:
            single["mpe2_simple_tag"] = f"not installed ({exc})"
        for _ in range(ROUNDS):
            for timer in timers.values():
                timer.chunk(max(100, args.steps))
        for name, timer in timers.items():
            single[name] = round(timer.median, 1)
            single[f"{name}_chunks"] = [round(r, 1) for r in timer.rates]
        if "mpe2_simple_tag" in timers:
            for name in ("pes_pettingzoo", "pes_pettingzoo_compiled"):
                if name in timers:
                    ratio = single[name] / single["mpe2_simple_tag"]
                    single[f"{name}_over_mpe2"] = round(ratio, 2)
        log(json.dumps({k: v for k, v in single.items() if not k.endswith("chunks")}))
        report["single_env_pettingzoo"] = single
        report["targets"] = {
            "pes_default_over_vmas at 64 envs": ">= 40",
            "pes_default_over_vmas at 1024 envs": ">= 20",
            "pes_pettingzoo_over_mpe2 (1 env)": ">= 2",
        }

    save(report, args.out)
    print(json.dumps(report, indent=2))
    return 0


def save(report: dict, path: str) -> None:
    """Write the report so far (after each batch size, so that a run cut off keeps its rows)."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json(out, report)  # atomically: a run stopped while writing keeps the rows before


if __name__ == "__main__":
    sys.exit(main())

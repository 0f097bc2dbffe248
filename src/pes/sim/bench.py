"""Simulator throughput: env-steps per second of the batched environment.

Method: random pursuer actions (drawn before timing), the configured evader, and episodes
desynchronised at the start (each environment begins at a random step of its episode) so that
the timed window contains auto-resets at their steady-state rate. After a warm-up that compiles
both the step and the auto-reset (when ``compile``), ``steps`` steps are timed in five chunks;
the reported rate is the median chunk's.
"""

from __future__ import annotations

import os
import platform
import statistics
import time
from collections.abc import Callable
from typing import Any

import torch

from pes.sim import scenario
from pes.sim.config import EnvConfig
from pes.sim.env import make_env


def machine_info(device: str = "cpu") -> dict[str, Any]:
    """What the numbers were measured on."""
    info = {
        "python": platform.python_version(),
        "torch": torch.__version__,
        "cpu": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
    }
    if device.startswith("cuda") and torch.cuda.is_available():
        info["gpu"] = torch.cuda.get_device_name(0)
    return info


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize()


def measure(
    config: EnvConfig,
    num_envs: int,
    device: str = "cpu",
    steps: int = 200,
    compile: bool = True,
    seed: int = 0,
) -> dict[str, Any]:
    """Throughput of ``num_envs`` environments; see the module docstring."""
    build = time.perf_counter()
    env = make_env(
        config, num_envs=num_envs, device=device, seed=seed, compile=compile, check_actions=False
    )
    env.reset(seed=seed)
    # Desynchronise the episodes: environment i starts at a random step of its episode.
    generator = torch.Generator().manual_seed(seed)
    start_step = torch.randint(0, config.max_steps, (num_envs,), generator=generator)
    if num_envs == 1:
        start_step[:] = config.max_steps - 3  # make the warm-up include one reset
    counters = env.state["counters"]
    counters[scenario.Counters._fields.index("step")] = start_step.to(env.device)
    pool = [
        torch.rand(num_envs, config.num_pursuers, 2, generator=generator) * 2 - 1 for _ in range(16)
    ]
    pool = [a.to(env.device) for a in pool]
    warmup_start = time.perf_counter()
    for k in range(8):
        env.step(pool[k % len(pool)])
    _sync(env.device)
    warmup = time.perf_counter() - warmup_start
    chunk = max(1, steps // 5)
    rates = []
    for _ in range(5):
        _sync(env.device)
        t0 = time.perf_counter()
        for k in range(chunk):
            env.step(pool[k % len(pool)])
        _sync(env.device)
        rates.append(chunk * num_envs / (time.perf_counter() - t0))
    return {
        "num_envs": num_envs,
        "env_steps_per_s": statistics.median(rates),
        "env_steps_per_s_chunks": [round(r, 1) for r in rates],
        "steps_timed": chunk * 5,
        "compile": env.compiled,
        "warmup_s": round(warmup, 2),
        "setup_s": round(warmup_start - build, 2),
    }


def run_benchmark(
    config: EnvConfig,
    sizes: list[int],
    device: str = "cpu",
    steps: int = 200,
    compile: bool = True,
    log: Callable[[str], None] | None = print,
) -> dict[str, Any]:
    """:func:`measure` at every batch size in ``sizes``; a JSON-friendly dict."""
    results = []
    for size in sizes:
        row = measure(config, size, device=device, steps=steps, compile=compile)
        results.append(row)
        if log:
            log(
                f"{size:>7} envs: {row['env_steps_per_s']:>12,.0f} env-steps/s "
                f"(warm-up {row['warmup_s']} s)"
            )
    return {
        "benchmark": "pes-sim",
        "device": device,
        "dynamics": config.dynamics,
        "physics_substeps": config.physics_substeps,
        "num_pursuers": config.num_pursuers,
        "evader_policy": config.evader_policy,
        "compile": compile,
        "machine": machine_info(device),
        "results": results,
    }

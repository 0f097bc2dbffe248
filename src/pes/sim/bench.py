"""Simulator throughput: env-steps per second of the batched environment.

Method: random pursuer actions (drawn before timing), the configured evader, and episodes
desynchronised at the start (each environment begins at a random step of its episode) so that
the timed window contains auto-resets at their steady-state rate. After a warm-up that compiles
both the step and the auto-reset (when ``compile``), steps are timed in chunks and the median
chunk's rate is reported. ``benchmarks/bench_sim.py`` interleaves these chunks with those of
other simulators, so that all are measured under the same conditions.
"""

from __future__ import annotations

import os
import platform
import statistics
import time
from collections.abc import Callable
from typing import Any, Optional

import torch

from pes.sim import scenario
from pes.sim.config import EnvConfig
from pes.sim.env import make_env


def cpu_model(cpuinfo: str) -> str | None:
    """The CPU that ``cpuinfo`` (the text of ``/proc/cpuinfo``) describes, as its model name
    and, where the file gives them, its family and model numbers and its widest vector
    instructions, e.g. ``AMD EPYC (family 25, model 1, AVX2)``: virtual machines often report
    only a vendor's line ("AMD EPYC"), which names CPUs of different speeds alike (the same
    training has taken 1.5 to 1.7 times the CPU time on one "AMD EPYC" as on another). None if
    the file names no model."""
    fields: dict[str, str] = {}
    for line in cpuinfo.splitlines():
        key, sep, value = line.partition(":")
        if sep and key.strip() not in fields:  # the first CPU's
            fields[key.strip()] = value.strip()
    name = fields.get("model name")
    if not name:
        return None
    flags = set(fields.get("flags", "").split())
    vector = next((v for f, v in VECTOR_FLAGS if f in flags), None)
    family, model = fields.get("cpu family"), fields.get("model")
    details = [f"family {family}, model {model}"] if family and model else []
    details += [vector] if vector else []
    return f"{name} ({', '.join(details)})" if details else name


VECTOR_FLAGS = (("avx512f", "AVX-512"), ("avx2", "AVX2"), ("avx", "AVX"))
"""``/proc/cpuinfo`` flags and the vector instructions they name, widest first."""


def machine_info(device: str = "cpu") -> dict[str, Any]:
    """What the numbers were measured on (the CPU as :func:`cpu_model` names it)."""
    info = {
        "python": platform.python_version(),
        "torch": torch.__version__,
        "cpu": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
    }
    try:
        with open("/proc/cpuinfo") as f:
            info["cpu"] = cpu_model(f.read()) or info["cpu"]
    except OSError:
        pass
    if device.startswith("cuda") and torch.cuda.is_available():
        info["gpu"] = torch.cuda.get_device_name(0)
    return info


class Timer:
    """Times chunks of calls to ``step`` (one call = ``per_call`` env-steps)."""

    def __init__(self, step: Callable[[], None], per_call: int,
                 sync: Callable[[], None] = lambda: None) -> None:  # fmt: skip
        self.step, self.per_call, self.sync = step, per_call, sync
        self.rates: list[float] = []

    def chunk(self, calls: int) -> float:
        """Run ``calls`` calls; record and return env-steps/s."""
        self.sync()
        start = time.perf_counter()
        for _ in range(calls):
            self.step()
        self.sync()
        rate = calls * self.per_call / (time.perf_counter() - start)
        self.rates.append(rate)
        return rate

    @property
    def median(self) -> float:
        return statistics.median(self.rates)


def pes_timer(config: EnvConfig, num_envs: int, device: str = "cpu", compile: bool = True,
              seed: int = 0) -> tuple[Timer, dict[str, float]]:  # fmt: skip
    """A :class:`Timer` of the batched environment, warmed up; and the set-up times."""
    start = time.perf_counter()
    env = make_env(config, num_envs=num_envs, device=device, seed=seed, compile=compile,
                   check_actions=False, wait_kernels=True)  # fmt: skip
    env.reset(seed=seed)
    # Desynchronise the episodes: environment i starts at a random step of its episode.
    generator = torch.Generator().manual_seed(seed)
    start_step = torch.randint(0, config.max_steps, (num_envs,), generator=generator)
    if num_envs == 1:
        start_step[:] = config.max_steps - 3  # make the warm-up include one reset
    env.state["counters"][scenario.Counters._fields.index("step")] = start_step.to(env.device)
    pool = [
        (torch.rand(num_envs, config.num_pursuers, 2, generator=generator) * 2 - 1).to(env.device)
        for _ in range(16)
    ]
    counter = [0]

    def step() -> None:
        env.step(pool[counter[0] % len(pool)])
        counter[0] += 1

    def sync() -> None:
        if env.device.type == "cuda":
            torch.cuda.synchronize()

    built = time.perf_counter()
    for _ in range(8):
        step()
    sync()
    return Timer(step, num_envs, sync), {
        "setup_s": round(built - start, 2),
        "warmup_s": round(time.perf_counter() - built, 2),
    }


def measure(config: EnvConfig, num_envs: int, device: str = "cpu", steps: int = 200,
            compile: bool = True, seed: int = 0) -> dict[str, Any]:  # fmt: skip
    """Throughput of ``num_envs`` environments (median of five chunks of ``steps / 5``)."""
    timer, times = pes_timer(config, num_envs, device, compile, seed)
    for _ in range(5):
        timer.chunk(max(1, steps // 5))
    return {
        "num_envs": num_envs,
        "env_steps_per_s": timer.median,
        "env_steps_per_s_chunks": [round(r, 1) for r in timer.rates],
        "compile": compile,
        **times,
    }


def run_benchmark(config: EnvConfig, sizes: list[int], device: str = "cpu", steps: int = 200,
                  compile: bool = True,
                  log: Optional[Callable[[str], None]] = print) -> dict[str, Any]:  # fmt: skip
    """:func:`measure` at every batch size in ``sizes``; a JSON-friendly dict."""
    results = []
    for size in sizes:
        if log:
            log(f"{size:>7} envs: warming up" + (" (compiling the step)" if compile else ""))
        row = measure(config, size, device=device, steps=steps, compile=compile)
        results.append(row)
        if log:
            log(f"{size:>7} envs: {row['env_steps_per_s']:>12,.0f} env-steps/s "
                f"(warm-up {row['warmup_s']} s)")  # fmt: skip
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

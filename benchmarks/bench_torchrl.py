"""Throughput of PES through TorchRL, beside the bare simulator and VMAS through TorchRL.

    python benchmarks/bench_torchrl.py   # CPU: writes benchmarks/results/torchrl_cpu.json
    python benchmarks/bench_torchrl.py --sim-compile \
        --out benchmarks/results/torchrl_cpu_compiled.json
    python benchmarks/bench_torchrl.py --device cuda --sizes 4096 65536 \
        --out benchmarks/results/torchrl_cuda.json

What is measured (frames per second; one frame = one control step of one game, TorchRL's
count of frames in a batch):

* ``pes_torchrl``: :class:`pes.torchrl.PESTorchRLEnv` as a user gets it (the simulator's step
  in the compiled CPU kernels of ``pes.sim.kernels``; with ``--sim-compile``, fused by
  ``torch.compile`` instead), stepped with ``env.step_and_maybe_reset`` as a TorchRL collector
  does, random actions drawn beforehand. Default scenario: 5 pursuers, flee
  evader, quadrotor dynamics with 10 sub-steps. Episodes desynchronised (each game starts at a
  random step of its episode) so that resets happen at their steady rate.
* ``pes_sim``: the same simulator without TorchRL (:func:`pes.make_env`, the same
  ``compile``), for the adapter's overhead (``torchrl_over_sim``).
* ``vmas_torchrl``: VMAS ``simple_tag`` (5 chasers, 1 runner, 8 landmarks, continuous actions)
  through TorchRL's ``VmasEnv``, stepped the same way, and ``vmas``, the same without TorchRL.
  Optional (``pip install vmas``).

The machine is shared and its speed drifts, so the four are timed in interleaved chunks and
each figure is the median of its chunks; the 1-minute load average before and after is in the
output (``load``) to judge how quiet the machine was.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_sim import vmas_timer  # noqa: E402

import pes  # noqa: E402
from pes.sim import scenario  # noqa: E402
from pes.sim.bench import Timer, machine_info, pes_timer  # noqa: E402
from pes.torchrl import GROUP, PESTorchRLEnv  # noqa: E402

ROUNDS = 5


def pes_torchrl_timer(
    config: pes.EnvConfig, num_envs: int, device: str, compile: bool
) -> tuple[Timer, dict]:
    """A warmed-up :class:`Timer` of ``step_and_maybe_reset`` on :class:`PESTorchRLEnv`."""
    start = time.perf_counter()
    env = PESTorchRLEnv(config, num_envs, device, seed=0, sim_compile=compile, check_actions=False)
    td = env.reset()
    generator = torch.Generator().manual_seed(0)
    start_step = torch.randint(0, config.max_steps, (num_envs,), generator=generator)
    start_step[0] = config.max_steps - 3  # the warm-up includes a reset (compiled there too)
    env.sim.state["counters"][scenario.Counters._fields.index("step")] = start_step.to(env.device)
    shape = (num_envs, config.num_pursuers, 2)
    pool = [(torch.rand(shape, generator=generator) * 2 - 1).to(env.device) for _ in range(16)]
    state = {"td": td, "i": 0}

    def step() -> None:
        td = state["td"].set((GROUP, "action"), pool[state["i"] % len(pool)])
        _, state["td"] = env.step_and_maybe_reset(td)
        state["i"] += 1

    built = time.perf_counter()
    for _ in range(8):
        step()
    return Timer(step, num_envs, _sync(device)), {
        "setup_s": round(built - start, 2),
        "warmup_s": round(time.perf_counter() - built, 2),
    }


def vmas_torchrl_timer(num_envs: int, device: str) -> Timer:
    """A warmed-up :class:`Timer` of ``step_and_maybe_reset`` on TorchRL's ``VmasEnv``."""
    from torchrl.envs.libs.vmas import VmasEnv

    env = VmasEnv(
        "simple_tag",
        num_envs=num_envs,
        device=device,
        continuous_actions=True,
        num_good_agents=1,
        num_adversaries=5,
        num_landmarks=8,
        seed=0,
    )
    td = env.reset()
    torch.manual_seed(0)
    pool = [env.full_action_spec.rand() for _ in range(8)]
    state = {"td": td, "i": 0}

    def step() -> None:
        td = state["td"].update(pool[state["i"] % len(pool)])
        _, state["td"] = env.step_and_maybe_reset(td)
        state["i"] += 1

    for _ in range(5):
        step()
    return Timer(step, num_envs, _sync(device))


def _sync(device: str):
    return torch.cuda.synchronize if device.startswith("cuda") else lambda: None


def _version(package: str) -> str | None:
    try:
        return importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return None


def log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 1024, 4096])
    parser.add_argument("--steps", type=int, default=200, help="timed steps per simulator")
    parser.add_argument("--skip-vmas", action="store_true")
    parser.add_argument(
        "--sim-compile", action="store_true", help="the simulator fused by torch.compile"
    )
    parser.add_argument("--out", default="benchmarks/results/torchrl_cpu.json")
    args = parser.parse_args()

    config = pes.EnvConfig().validate()
    load_before = os.getloadavg()
    report: dict = {
        "benchmark": "frames/s through TorchRL (one frame = one control step of one game), "
        "medians of interleaved chunks",
        "command": " ".join(["python"] + sys.argv),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "device": args.device,
        "machine": machine_info(args.device),
        "versions": {p: _version(p) for p in ("torch", "torchrl", "tensordict", "vmas")},
        "scenario": "PES: default EnvConfig (5 pursuers with random actions, flee evader, "
        "quadrotor dynamics with 10 sub-steps, 8 buildings), simulator "
        + ("fused by torch.compile" if args.sim_compile else "in its CPU kernels (the default)")
        + "; VMAS: "
        "simple_tag with 5 chasers, 1 runner, 8 landmarks, continuous random actions",
        "sizes": [],
    }
    for size in args.sizes:
        row: dict = {"num_envs": size}
        timers: dict[str, Timer] = {}
        timers["pes_torchrl"], row["pes_torchrl_setup"] = pes_torchrl_timer(
            config, size, args.device, args.sim_compile
        )
        timers["pes_sim"], row["pes_sim_setup"] = pes_timer(
            config, size, args.device, compile=args.sim_compile
        )
        if not args.skip_vmas:
            try:
                timers["vmas_torchrl"] = vmas_torchrl_timer(size, args.device)
                timers["vmas"] = vmas_timer(size, args.device)
            except ImportError as exc:
                row["vmas"] = f"not installed ({exc})"
        calls = max(4, args.steps // ROUNDS) if size >= 1024 else max(20, args.steps // ROUNDS)
        for _ in range(ROUNDS):
            for timer in timers.values():
                timer.chunk(calls)
        for name, timer in timers.items():
            row[name] = round(timer.median, 1)
            row[f"{name}_chunks"] = [round(r, 1) for r in timer.rates]
        row["torchrl_over_sim"] = round(row["pes_torchrl"] / row["pes_sim"], 3)
        if "vmas_torchrl" in timers:
            row["pes_over_vmas_torchrl"] = round(row["pes_torchrl"] / row["vmas_torchrl"], 2)
        log(json.dumps({k: v for k, v in row.items() if not k.endswith("chunks")}))
        report["sizes"].append(row)
    report["load"] = {
        "loadavg_1_5_15_before": [round(x, 2) for x in load_before],
        "loadavg_1_5_15_after": [round(x, 2) for x in os.getloadavg()],
    }

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The compiled CPU kernels of the step (pes.sim.kernels) against the torch code they replace."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

import pes
from pes.sim import kernels
from pes.sim.config import EnvConfig


@pytest.fixture
def torch_loop(monkeypatch):
    """A switch between the two paths for the environments made next: ``use(True)`` the
    kernel, ``use(False)`` torch."""

    def use(kernel: bool) -> None:
        monkeypatch.setattr(kernels, "_ENABLED", kernel)

    yield use


def test_kernel_is_used_on_the_cpu():
    assert kernels.usable(torch.device("cpu")) and not kernels.usable(torch.device("meta"))
    assert pes.make_env(num_envs=2, seed=0).scenario.kernels
    assert kernels.applies(torch.zeros(2))
    assert not kernels.applies(torch.zeros(2, dtype=torch.float64))
    assert not kernels.applies(torch.zeros(2, requires_grad=True))


FIRST_RUN = """
import torch, pes
from pes.sim import kernels
env = pes.make_env(num_envs=2, seed=0)
env.reset()
env.step(torch.zeros(2, 5, 2))
print("torch first:", not env.scenario.kernels, kernels._child is not None)
kernels._child.wait()  # the background compilation
env.step(torch.zeros(2, 5, 2))
later = pes.make_env(num_envs=2, seed=0)
later.reset()
later.step(torch.zeros(2, 5, 2))
print("kept:", not env.scenario.kernels, later.scenario.kernels, kernels.ready_marker().is_file())
"""

LATER_RUN = """
import torch, pes
from pes.sim import kernels
env = pes.make_env(num_envs=2, seed=0)
env.reset()
hits = sum(kernels._step.observe.stats.cache_hits.values())  # loaded, not compiled again
print("kernels first:", kernels.serving(), hits > 0)
"""


@pytest.mark.slow
def test_a_machine_without_compiled_kernels_steps_at_once_and_compiles_them_aside(tmp_path):
    """With no compiled kernels (an empty Numba cache, as on a new machine) the first step does
    not wait for a compilation: its environment runs the torch code while a background process
    compiles the kernels, and keeps it (a run never switches paths); an environment made once
    the compilation is done uses them; the next process loads them from the cache before its
    first step."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}

    def run(script: str) -> str:
        done = subprocess.run(
            [sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=900
        )
        assert done.returncode == 0, done.stderr[-2000:]
        return done.stdout

    assert not list(tmp_path.glob("pes-kernels-*.ready"))
    assert "torch first: True True" in (first := run(FIRST_RUN)), first
    assert "kept: True True True" in first
    assert len(list(tmp_path.glob("pes-kernels-*.ready"))) == 1
    assert "kernels first: True True" in run(LATER_RUN)


def _same(a: torch.Tensor, b: torch.Tensor) -> bool:
    """Equal for flags and counters, equal to float32 rounding for numbers (on the CPU)."""
    a, b = a.cpu(), b.cpu()
    if a.is_floating_point():
        return torch.allclose(a, b, rtol=1e-5, atol=1e-5)
    return torch.equal(a, b)


def _assert_same_step(step_a: tuple, state_a: dict, step_b: tuple, state_b: dict) -> None:
    """Two steps from the same state and actions: the same outputs (obs, reward, terminated,
    truncated, info) and the same next state, by :func:`_same`."""
    for name, a, b in zip(("obs", "reward", "terminated", "truncated"), step_a, step_b):
        assert _same(a, b), name
    for key, value in step_b[4].items():
        assert _same(step_a[4][key], value), key
    for key, value in state_b.items():
        assert _same(state_a[key], value), key


STEP_CONFIGS = [
    EnvConfig(max_steps=40),
    EnvConfig(disturbance=True, evader_policy="ddpg", num_pursuers=4, damaged=1),
    EnvConfig(
        disturbance=True,
        crash_mode="disable",
        approach_weight=0.3,
        safe_distance=1.5,
        capture_reward=25.0,
        crash_reward=-10.0,
        max_steps=30,
    ),
    EnvConfig(intercept_lead=1.0, encirclement_weight=0.5, evader_policy="random"),
    EnvConfig(dynamics="point_mass", num_pursuers=3, capture_count=2),
    EnvConfig(distance_metric="geodesic"),  # torch around the sub-step kernel alone
]
STEP_IDS = [
    "flee-resets",
    "disturbance-ddpg-damaged",
    "pes-reward-disable",
    "lead-encircle",
    "point",
    "geodesic",
]


@pytest.mark.parametrize("config", STEP_CONFIGS, ids=STEP_IDS)
def test_kernels_step_as_torch(config, torch_loop):
    """From the same states and actions the two paths give the same flags, counters and
    resets, and the same numbers to float32 rounding (torch's vectorised square root is not
    always correctly rounded; the kernels' is): observations, rewards, info and next state."""
    torch_loop(True)
    fast = pes.make_env(config, num_envs=37, seed=5)
    torch_loop(False)
    slow = pes.make_env(config, num_envs=37, seed=5)
    assert fast.scenario.kernels and not slow.scenario.kernels
    fast.reset(seed=5)
    generator = torch.Generator().manual_seed(0)
    for _ in range(70):
        actions = torch.rand(37, config.num_pursuers, 2, generator=generator) * 2 - 1
        slow.set_state(fast.get_state())
        by_kernel = fast.step(actions)
        by_torch = slow.step(actions)
        _assert_same_step(by_kernel, fast.get_state(), by_torch, slow.get_state())


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
@pytest.mark.parametrize("config", STEP_CONFIGS, ids=STEP_IDS)
def test_cuda_steps_as_the_cpu(config, torch_loop):
    """The CUDA step against the CPU's torch code (which the test above ties to the kernels):
    from the same states and actions, the same flags, counters and resets, and the same
    numbers to float32 rounding."""
    torch_loop(False)
    cpu = pes.make_env(config, num_envs=37, seed=5)
    gpu = pes.make_env(config, num_envs=37, seed=5, device="cuda")
    cpu.reset(seed=5)
    gpu.reset(seed=5)
    generator = torch.Generator().manual_seed(0)
    for _ in range(70):
        actions = torch.rand(37, config.num_pursuers, 2, generator=generator) * 2 - 1
        gpu.set_state(cpu.get_state())
        by_cpu = cpu.step(actions)
        by_gpu = gpu.step(actions.cuda())
        _assert_same_step(by_cpu, cpu.get_state(), by_gpu, gpu.get_state())


def test_torch_loop_still_serves_float64_and_gradients(torch_loop):
    """What the kernel does not serve goes through the torch loop unchanged."""
    from pes.sim.dynamics import GRAVITY, Vehicles, quadrotor_step
    from pes.sim.scenario import build_scenario

    sc = build_scenario(EnvConfig(), torch.device("cpu"))
    fields = [torch.zeros(1, 6, requires_grad=(i == 0)) for i in range(16)]
    v = Vehicles(*fields)
    ax = torch.full((1, 6), 1.0)
    out = quadrotor_step(v, ax, ax * 0, ax * 0, ax * 0, sc.params, 0.1, 10, use_kernels=True)
    assert out.x.requires_grad and out.vx[0, 0] > 0
    assert GRAVITY > 0


def test_a_new_compilation_clears_the_cached_code_of_both_kernel_modules_and_nothing_else(
    tmp_path,
):
    """Numba keys a function's cache on its own source file: ``move`` inlines the sub-steps of
    _numba_substeps.py, so a compilation for new sources removes both modules' cached code
    first (in the folders where Numba keeps it), and leaves every other file alone."""
    assert kernels.wait()
    folders = kernels._cache_folders()
    assert any(any(Path(f).glob("_numba_step.move-*.nbi")) for f in folders)
    stale = [
        "_numba_step.move-356.py311.nbi",
        "_numba_step.move-356.py311.1.nbc",
        "_numba_substeps.block_substeps-44.py311.nbi",
        "_numba_substeps.block_substeps-44.py311.2.nbc",
    ]
    kept = [
        "_numba_step.py",
        "_numba_stepper.f-1.py311.nbi",
        "other._numba_step.f-1.py311.nbc",
        "evader.f-3.py311.nbi",
        "pes-kernels-0123456789abcdef.ready",
    ]
    for name in stale + kept:
        (tmp_path / name).touch()
    kernels.clear_cache([tmp_path, tmp_path / "missing"])
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(kept)


def test_the_ready_marker_keys_on_every_file_the_kernels_compile_from():
    """A module of PES whose functions the kernels call (the reward's terms, the sub-steps) is
    compiled into their cached machine code: a change of it must need a new ready marker, or
    the kernels would run its old code."""
    import ast

    here = Path(kernels.__file__).parent
    compiled = set()
    for name in ("_numba_step.py", "_numba_substeps.py"):
        for node in ast.walk(ast.parse((here / name).read_text())):
            if isinstance(node, ast.ImportFrom) and node.module == "pes.sim":
                compiled.update(f"{alias.name}.py" for alias in node.names)
    assert compiled == {"_numba_substeps.py", "reward.py"}
    assert compiled <= set(kernels._SOURCES)

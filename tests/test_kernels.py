"""The compiled CPU sub-step loop (pes.sim.kernels) against the torch loop it replaces."""

from __future__ import annotations

import pytest
import torch

import pes
from pes.sim import kernels
from pes.sim.config import EnvConfig


@pytest.fixture
def torch_loop(monkeypatch):
    """A switch between the two paths: ``use(True)`` the kernel, ``use(False)`` torch."""

    def use(kernel: bool) -> None:
        monkeypatch.setattr(kernels, "_ENABLED", kernel)

    yield use


def test_kernel_is_used_on_the_cpu():
    assert kernels.available(torch.zeros(2))
    assert not kernels.available(torch.zeros(2, dtype=torch.float64))
    assert not kernels.available(torch.zeros(2, requires_grad=True))


@pytest.mark.parametrize(
    "config",
    [
        EnvConfig(),
        EnvConfig(disturbance=True, evader_policy="ddpg", num_pursuers=4, damaged=1),
    ],
    ids=["default", "disturbance-ddpg-damaged"],
)
def test_kernel_steps_bit_for_bit_as_torch(config, torch_loop):
    """From the same states and actions the two paths give identical states: the kernel
    repeats torch's float32 arithmetic operation by operation."""
    env = pes.make_env(config, num_envs=37, seed=5)
    env.reset(seed=5)
    generator = torch.Generator().manual_seed(0)
    for _ in range(60):
        actions = torch.rand(37, config.num_pursuers, 2, generator=generator) * 2 - 1
        start = {k: v.clone() for k, v in env.get_state().items()}
        torch_loop(True)
        env.step(actions)
        by_kernel = {k: v.clone() for k, v in env.get_state().items()}
        env.set_state(start)
        torch_loop(False)
        env.step(actions)
        for key, value in env.get_state().items():
            assert torch.equal(value, by_kernel[key]), key


def test_torch_loop_still_serves_float64_and_gradients(torch_loop):
    """What the kernel does not serve goes through the torch loop unchanged."""
    from pes.sim.dynamics import GRAVITY, Vehicles, quadrotor_step
    from pes.sim.scenario import build_scenario

    sc = build_scenario(EnvConfig(), torch.device("cpu"))
    fields = [torch.zeros(1, 6, requires_grad=(i == 0)) for i in range(16)]
    v = Vehicles(*fields)
    ax = torch.full((1, 6), 1.0)
    out = quadrotor_step(v, ax, ax * 0, ax * 0, ax * 0, sc.params, 0.1, 10)
    assert out.x.requires_grad and out.vx[0, 0] > 0
    assert GRAVITY > 0

"""The fused (torch.compile) step against the eager reference."""

from __future__ import annotations

import pytest
import torch

import pes


@pytest.mark.slow
def test_compiled_step_matches_eager_through_resets():
    cfg = pes.EnvConfig(
        disturbance=True, max_steps=25, damaged=1, damage_step="random", crash_mode="disable"
    ).validate()
    fused = pes.make_env(cfg, num_envs=16, seed=7, compile=True)
    eager = pes.make_env(cfg, num_envs=16, seed=7)
    fused.reset()
    eager.reset()
    gen = torch.Generator().manual_seed(1)
    resets = 0
    for _ in range(60):
        actions = torch.rand(16, 5, 2, generator=gen) * 2 - 1
        a = fused.step(actions)
        b = eager.step(actions)
        assert torch.allclose(a[0], b[0], atol=1e-4)
        assert torch.allclose(a[1], b[1], atol=1e-4)
        assert torch.equal(a[2], b[2]) and torch.equal(a[3], b[3])
        resets += int((a[2] | a[3]).sum())
    assert resets >= 16  # the auto-reset pass ran, compiled
    assert fused.compiled and not eager.compiled  # no silent fall-back to eager


def test_a_broken_compiler_falls_back_to_eager_and_says_so():
    env = pes.make_env(num_envs=2, seed=0, compile=True)
    assert env.compiled

    def broken(*args):
        raise RuntimeError("no compiler here")

    env._step_fn.fused = broken  # what a machine without a working compiler does
    env.reset()
    with pytest.warns(UserWarning, match="running eagerly"):
        obs, *_ = env.step(torch.zeros(2, 5, 2))
    assert torch.isfinite(obs).all()
    assert not env.compiled

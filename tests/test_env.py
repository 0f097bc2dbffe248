"""The batched environment: API, auto-reset, determinism, parity, masks, bad actions."""

from __future__ import annotations

import pytest
import torch

import pes
from pes.errors import ActionError, PESError
from pes.sim import scenario


def test_shapes_and_info(small_config):
    env = pes.make_env(small_config, num_envs=3, seed=0)
    obs, info = env.reset()
    assert obs.shape == (3, 5, 5, 8) and obs.dtype == torch.float32
    assert info["obs_mask"].shape == (3, 5, 5) and info["state"].shape == (3, 6, 8)
    assert info["history"].shape == (3, 10, 6, 4)
    assert env.obs_shape == (5, 5, 8) and env.action_shape == (5, 2)
    assert env.agents == [f"pursuer_{i}" for i in range(5)]
    obs, reward, term, trunc, info = env.step(torch.zeros(3, 5, 2))
    assert reward.shape == (3, 5) and term.shape == trunc.shape == (3,)
    for key in (
        "success",
        "steps",
        "crashes",
        "alive",
        "distances",
        "crashed",
        "final_obs",
        "final_state",
        "positions",
        "velocities",
        "evader_reward",
    ):
        assert key in info, key
    assert info["alive"].shape == (3, 5) and info["distances"].shape == (3, 5)


def test_observation_rows_follow_table_1():
    env = pes.make_env({"layout": "empty"}, num_envs=1, seed=1)
    obs, info = env.reset()
    pos, arena = env.positions[0], 100.0
    o = obs[0]
    # Pursuer 2's own row: absolute position, velocity, vector to the evader.
    assert torch.allclose(o[2, 0, :2], pos[2] / arena, atol=1e-6)
    assert torch.allclose(o[2, 0, 6:8], (pos[5] - pos[2]) / arena, atol=1e-6)
    # Its row 1 is pursuer 0, relative to pursuer 2; pursuer 0's vector to the evader.
    assert torch.allclose(o[2, 1, :2], (pos[0] - pos[2]) / arena, atol=1e-6)
    assert torch.allclose(o[2, 1, 6:8], (pos[5] - pos[0]) / arena, atol=1e-6)
    # Vector to the nearest obstacle: with no buildings, the nearest wall.
    x, y = pos[0].tolist()
    nearest = min(x, 100 - x, y, 100 - y)
    assert float(o[0, 0, 4:6].norm() * arena) == pytest.approx(nearest, abs=1e-3)
    assert info["obs_mask"].all()


def test_start_positions_follow_the_rules():
    cfg = pes.EnvConfig().validate()
    env = pes.make_env(cfg, num_envs=256, seed=5)
    env.reset()
    pos = env.positions
    edge = torch.minimum(
        torch.minimum(pos[..., 0], 100 - pos[..., 0]), torch.minimum(pos[..., 1], 100 - pos[..., 1])
    )
    assert (edge[:, :5] <= cfg.pursuer_spawn_band + 1e-4).all()
    assert ((pos[:, 5] - 50).norm(dim=-1) <= cfg.evader_spawn_radius + 1e-4).all()
    v, _, _ = scenario.unpack(env.state)
    assert (v.obstacle_dist >= cfg.body_radius + cfg.spawn_clearance - 1e-4).all()
    assert env.velocities.abs().max() == 0
    # Spread over the whole start band, not a few points.
    assert pos[:, :5].reshape(-1, 2).unique(dim=0).shape[0] == 256 * 5


def test_auto_reset_keeps_the_final_observation():
    cfg = pes.EnvConfig(max_steps=7).validate()
    env = pes.make_env(cfg, num_envs=4, seed=0)
    obs, _ = env.reset()
    actions = torch.zeros(4, 5, 2)
    for _ in range(7):
        last = env.positions.clone()
        obs, _, term, trunc, info = env.step(actions)
    assert trunc.all() and not term.any()
    assert (info["steps"] == 7).all()
    # The returned observation starts the next episode; the final one is in info.
    assert not torch.allclose(obs, info["final_obs"])
    assert torch.allclose(info["final_obs"][:, :, 0, :2] * 100, info["positions"][:, :5], atol=1e-4)
    assert torch.allclose(obs[:, :, 0, :2] * 100, env.positions[:, :5], atol=1e-4)
    assert not torch.allclose(env.positions, last)
    assert (info["history"][:, :-1] == 0).all()  # zero-padded at the start of an episode
    # 7 steps plus the start frame fill the last 8 of the 10 history frames.
    assert (info["final_history"][:, :2] == 0).all() and (info["final_history"][:, 2] != 0).any()
    _, _, _, _, info = env.step(actions)
    assert (info["steps"] == 1).all()


def test_same_seed_same_trajectories():
    cfg = pes.EnvConfig(disturbance=True, max_steps=40).validate()
    runs = []
    for _ in range(2):
        env = pes.make_env(cfg, num_envs=5, seed=11)
        env.reset()
        gen = torch.Generator().manual_seed(3)
        trace = []
        for _ in range(90):
            obs, reward, *_ = env.step(torch.rand(5, 5, 2, generator=gen) * 2 - 1)
            trace.append((obs.clone(), reward.clone()))
        runs.append(trace)
    for (o1, r1), (o2, r2) in zip(*runs):
        assert torch.equal(o1, o2) and torch.equal(r1, r2)
    env = pes.make_env(cfg, num_envs=5, seed=12)
    obs, _ = env.reset()
    assert not torch.equal(obs, runs[0][0][0])


def test_batched_matches_single_environments():
    """Environment i of a batch seeded s behaves as a single environment seeded s + i."""
    cfg = pes.EnvConfig(
        disturbance=True, max_steps=30, damaged=1, damage_step="random", crash_mode="disable"
    ).validate()
    batch = pes.make_env(cfg, num_envs=4, seed=100)
    batch.reset()
    singles = [pes.make_env(cfg, num_envs=1, seed=100 + i) for i in range(4)]
    for s in singles:
        s.reset()
    gen = torch.Generator().manual_seed(0)
    for _ in range(70):  # more than two episodes: auto-resets included
        actions = torch.rand(4, 5, 2, generator=gen) * 2 - 1
        obs, reward, term, trunc, _ = batch.step(actions)
        for i, s in enumerate(singles):
            o, r, te, tr, _ = s.step(actions[i : i + 1])
            assert torch.allclose(o[0], obs[i], atol=1e-5)
            assert torch.allclose(r[0], reward[i], atol=1e-5)
            assert bool(te[0]) == bool(term[i]) and bool(tr[0]) == bool(trunc[i])


def test_reset_without_seed_moves_to_new_episodes():
    env = pes.make_env(num_envs=2, seed=0)
    a, _ = env.reset()
    b, _ = env.reset()
    c, _ = env.reset(seed=0)
    assert not torch.equal(a, b) and torch.equal(a, c)


def test_damaged_pursuers_are_masked_from_the_start():
    cfg = pes.EnvConfig(damaged=2).validate()
    env = pes.make_env(cfg, num_envs=32, seed=0)
    obs, info = env.reset()
    alive = info["alive"]
    assert (alive.sum(-1) == 3).all()
    assert len({tuple(a.tolist()) for a in alive}) > 1  # random pursuers
    mask = info["obs_mask"]
    dead = ~alive
    assert not mask[dead].any()
    assert obs[dead].abs().max() == 0
    # A dead pursuer's rows in the others' observations are zero.
    idx = env.scenario.other_index
    assert not (mask & dead[:, idx]).any()


def test_damage_at_a_given_step():
    cfg = pes.EnvConfig(damaged=1, damage_step=10, max_steps=60).validate()
    env = pes.make_env(cfg, num_envs=8, seed=0)
    _, info = env.reset()
    assert info["alive"].all()
    for k in range(10):
        _, _, _, _, info = env.step(torch.zeros(8, 5, 2))
        assert (info["alive"].sum(-1) == (5 if k < 9 else 4)).all()


def test_bad_actions_are_rejected():
    env = pes.make_env(num_envs=2, seed=0)
    with pytest.raises(PESError, match="reset"):
        env.step(torch.zeros(2, 5, 2))
    env.reset()
    with pytest.raises(ActionError, match="shape"):
        env.step(torch.zeros(2, 4, 2))
    with pytest.raises(ActionError, match="shape"):
        env.step(torch.zeros(5, 2))
    bad = torch.zeros(2, 5, 2)
    bad[1, 3, 0] = float("nan")
    with pytest.raises(ActionError, match="NaN"):
        env.step(bad)
    bad[1, 3, 0] = float("inf")
    with pytest.raises(ActionError, match="NaN"):
        env.step(bad)
    with pytest.raises(ActionError, match="floating"):
        env.step(torch.zeros(2, 5, 2, dtype=torch.long))
    with pytest.raises(ActionError, match="external"):
        env.step(torch.zeros(2, 5, 2), evader_actions=torch.zeros(2, 2))
    ext = pes.make_env({"evader_policy": "external"}, num_envs=2, seed=0)
    ext.reset()
    with pytest.raises(ActionError, match="evader_actions"):
        ext.step(torch.zeros(2, 5, 2))
    # Lists are accepted and converted.
    env.step([[[0.0, 0.0]] * 5] * 2)


@pytest.mark.parametrize("n", [1, 2, 8, 32])
def test_any_number_of_pursuers(n):
    cfg = pes.EnvConfig(num_pursuers=n, capture_count=min(3, n), max_steps=20).validate()
    env = pes.make_env(cfg, num_envs=3, seed=0)
    obs, _ = env.reset()
    assert obs.shape == (3, n, n, 8)
    for _ in range(25):
        obs, reward, *_ = env.step(torch.rand(3, n, 2) * 2 - 1)
    assert reward.shape == (3, n) and obs.isfinite().all()


def test_cuda_if_available():
    if not torch.cuda.is_available():
        pytest.skip("no CUDA device here (checked on a GPU machine; see benchmarks/)")
    env = pes.make_env(num_envs=64, device="cuda", seed=0)
    obs, _ = env.reset()
    obs, reward, *_ = env.step(torch.zeros(64, 5, 2, device="cuda"))
    assert obs.is_cuda and reward.is_cuda

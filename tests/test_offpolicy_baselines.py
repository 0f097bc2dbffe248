"""The off-policy baselines of Table IV: MADDPG, independent DDPG and BiCNet -- their networks,
masking of damaged pursuers, tiny training runs, resumption and a small learning test each."""

from __future__ import annotations

import json

import pytest
import torch

import pes
from pes.algos import ALGOS, PURSUER_ALGOS, build_train_config, train
from pes.algos.bicnet import BiCNetActor
from pes.algos.ddpg import LocalCritics
from pes.algos.loading import load_pursuer_policy
from pes.algos.maddpg import CentralCritics, EnsembleMLP, MLPActors
from pes.cli import main
from pes.errors import CheckpointError, ConfigError
from pes.learn.features import pursuer_obs
from tests.learning import FAST, assert_learns

BASELINES = ("maddpg", "ddpg", "bicnet")


def _state(n: int, num_envs: int = 6, damaged: int = 0, seed: int = 0):
    cfg = pes.EnvConfig(num_pursuers=n, capture_count=min(3, n), damaged=damaged)
    env = pes.make_env(cfg.replace(crash_mode="disable"), num_envs=num_envs, seed=seed)
    obs, info = env.reset()
    return obs, info


def test_registered_with_presets():
    for algo in BASELINES:
        assert algo in ALGOS and algo in PURSUER_ALGOS
        for preset in ("paper", "quick", "tiny"):
            cfg = build_train_config(algo, preset)
            assert not hasattr(cfg.learner, "tp_hidden")  # no TP Net
    assert not build_train_config("maddpg", "quick").learner.shared  # one actor/critic each
    paper = build_train_config("maddpg", "paper").learner
    assert (paper.gamma, paper.lr_actor, paper.tau, paper.batch_size) == (0.95, 1e-3, 1e-2, 512)


def test_ensemble_members_are_independent():
    torch.manual_seed(0)
    net = EnsembleMLP(3, [4, 8, 2])
    x = torch.randn(3, 5, 4)
    before = net(x)
    with torch.no_grad():
        net.layers[0].weight[1].add_(1.0)
    after = net(x)
    assert torch.equal(before[[0, 2]], after[[0, 2]]) and not torch.equal(before[1], after[1])
    shared = EnsembleMLP(1, [4, 8, 2])  # one member serves every agent's slice
    torch.testing.assert_close(shared(x)[2], shared(x[2:3])[0])


def test_maddpg_critic_is_central_and_ddpg_critic_is_local():
    cfg = build_train_config("maddpg", "tiny")
    torch.manual_seed(0)
    central, local = CentralCritics(cfg.learner, 5), LocalCritics(cfg.learner, 5)
    _, info = _state(5)
    state, alive = info["state"], info["obs_mask"][:, :, 0]
    a = torch.rand(6, 5, 2) * 2 - 1
    b = a.clone()
    b[:, 3] = -b[:, 3]  # pursuer 3 acts differently
    for critic, others_see_it in ((central, True), (local, False)):
        qa, qb = critic(state, alive, a), critic(state, alive, b)
        assert qa.shape == (6, 5)
        assert not torch.allclose(qa[:, 3], qb[:, 3])
        assert torch.allclose(qa[:, [0, 1, 2, 4]], qb[:, [0, 1, 2, 4]]) != others_see_it


@pytest.mark.parametrize("algo", BASELINES)
def test_damaged_pursuers_are_masked(algo):
    """Dead pursuers' actions never change the alive pursuers' Qs, and their own rows never
    change the alive pursuers' actions."""
    cfg = build_train_config(algo, "tiny")
    learner = ALGOS[algo](cfg, pes.EnvConfig(), "cpu")
    obs, info = _state(5, damaged=2, seed=4)
    state, alive = info["state"], info["obs_mask"][:, :, 0]
    assert (~alive).sum(-1).eq(2).all()
    a = torch.rand(6, 5, 2) * 2 - 1
    b = torch.where(alive.unsqueeze(-1), a, -a)
    with torch.no_grad():
        qa, qb = learner.critic(state, alive, a, None), learner.critic(state, alive, b, None)
        torch.testing.assert_close(qa[alive], qb[alive])
        # garbage in a dead pursuer's state row is not seen by the actors of the alive ones
        junk = state.clone()
        junk[:, :5][~alive] = 7.0
        obs2, mask2 = pursuer_obs(junk, alive)
        torch.testing.assert_close(obs2, obs)
        act1 = learner.actor(obs, info["obs_mask"], None)
        act2 = learner.actor(obs2, mask2, None)
        torch.testing.assert_close(act1[alive], act2[alive])


def test_bicnet_serves_any_swarm_size_and_maddpg_does_not(tmp_path):
    cfg = build_train_config("bicnet", "tiny")
    torch.manual_seed(0)
    actor = BiCNetActor(cfg.learner)
    for n in (1, 3, 8):
        obs, info = _state(n, num_envs=2)
        assert actor(obs, info["obs_mask"]).shape == (2, n, 2)
    mlp = MLPActors(build_train_config("maddpg", "tiny").learner, 5)
    obs, info = _state(5, num_envs=2)
    assert mlp(obs, info["obs_mask"]).abs().max() < 0.01  # small last layer: it starts hovering
    for algo in BASELINES:
        train(
            build_train_config(algo, "tiny", dict(FAST, episodes=8, eval_episodes=0)),
            tmp_path / algo,
            progress=False,
        )
    load_pursuer_policy(tmp_path / "bicnet", pes.EnvConfig(num_pursuers=4))
    for algo in ("maddpg", "ddpg"):
        with pytest.raises(CheckpointError, match="sized for 5 pursuers"):
            load_pursuer_policy(tmp_path / algo, pes.EnvConfig(num_pursuers=4))


def test_unshipped_algorithm_name_is_a_clear_error(capsys):
    assert main(["eval", "--policy", "maddpg", "--episodes", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no 'maddpg' model is shipped" in err[0]


def test_bad_settings_are_refused():
    """A key the method does not read is an error naming the method."""
    for algo, key in (("bicnet", "shared"), ("bicnet", "actor_gradient"), ("maddpg", "lr_tp")):
        with pytest.raises(ConfigError, match=f"unknown key '{key}' for {algo}"):
            build_train_config(algo, "tiny", {key: 1})


@pytest.mark.parametrize("algo", BASELINES)
def test_trains_resumes_and_evaluates(algo, tmp_path, capsys):
    """A tiny run with n-step TD targets, resumed to a larger budget; its checkpoint evaluates
    through ``pes eval`` (its policy file is loaded in the test above)."""
    run = tmp_path / "run"
    first = train(
        build_train_config(algo, "tiny", dict(FAST, episodes=8, eval_episodes=0, n_step=2)),
        run,
        progress=False,
    )
    assert first["updates"] > 0 and first["algo"] == algo
    ckpt = torch.load(run / "checkpoint.pt", weights_only=True)
    assert ckpt["algo"] == algo and ckpt["buffer"]["filled"] > 0
    cfg = build_train_config(algo, "tiny", dict(FAST, episodes=16, eval_episodes=4, n_step=2))
    done = train(cfg, run, resume=True, progress=False)
    assert done["episodes"] >= 16 and done["updates"] > first["updates"]
    assert done["env_steps"] > first["env_steps"] and done["eval"]["episodes"] == 4
    rows = (run / "progress.csv").read_text().splitlines()
    assert sum(r.startswith("episodes") for r in rows) == 1 and len(rows) >= 2
    argv = ["eval", "--policy", str(run / "checkpoint.pt"), "--episodes", "2", "--json"]
    assert main([*argv, "--set", "max_steps=20"]) == 0
    assert json.loads(capsys.readouterr().out)["episodes"] == 2
    with pytest.raises(CheckpointError, match="different settings"):
        other = build_train_config(algo, "tiny", dict(FAST, mlp_hidden=48, n_step=2, episodes=24))
        train(other, run, resume=True, progress=False)


@pytest.mark.slow
@pytest.mark.parametrize("algo", BASELINES)
def test_learns_on_a_tiny_budget(algo, tmp_path):
    """Fixed seed, 15-30 s each: CBC-TP's learning check (tests/learning.py)."""
    assert_learns(algo, tmp_path / "run", episodes=200)

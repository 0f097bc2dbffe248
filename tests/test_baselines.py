"""The PPO and MAAC baselines: their shared pieces (rollout storage, GAE, squashed Gaussian,
attention critic), a tiny run of each through train/eval/resume, and learning tests."""

from __future__ import annotations

import json

import pytest
import torch

import pes
from pes.algos import build_train_config, train
from pes.algos.loading import load_pursuer_policy
from pes.algos.maac import AttentionCritic, SquashedGaussianActor
from pes.cli import main
from pes.errors import CheckpointError, ConfigError
from pes.learn.buffer import RolloutBuffer, gae
from tests.learning import FAST, assert_learns

BASELINES = ("ppo", "mappo", "maac")


def test_gae_matches_a_hand_computation():
    gamma, lam = 0.9, 0.8
    reward = torch.tensor([[1.0], [2.0], [3.0], [4.0]])
    value = torch.tensor([[0.5], [1.0], [1.5], [2.0]])
    nonterminal = torch.tensor([[1.0], [0.0], [1.0], [1.0]])  # the episode ends after step 1
    last = torch.tensor([10.0])
    adv, ret = gae(reward, value, nonterminal, last, gamma, lam)
    expect = [0.0] * 4
    following, running = last.item(), 0.0
    for t in (3, 2, 1, 0):
        keep = nonterminal[t, 0].item()
        delta = reward[t, 0].item() + gamma * keep * following - value[t, 0].item()
        running = delta + gamma * lam * keep * running
        expect[t], following = running, value[t, 0].item()
    torch.testing.assert_close(adv[:, 0], torch.tensor(expect))
    torch.testing.assert_close(ret, adv + value)
    assert adv[1, 0].item() == pytest.approx(2.0 - 1.0)  # cut: r - V, nothing bootstrapped


def test_rollout_buffer_fills_clears_and_checkpoints_a_partial_rollout():
    buf = RolloutBuffer(3, 2, {"x": ((2,), torch.float32)})
    for i in range(3):
        assert not buf.full
        buf.add(x=torch.full((2, 2), float(i)))
    assert buf.full and len(buf) == 6 and buf.data["x"][2, 1, 0] == 2.0
    with pytest.raises(RuntimeError, match="full"):
        buf.add(x=torch.zeros(2, 2))
    buf.clear()
    buf.add(x=torch.full((2, 2), 7.0))
    state = buf.state_dict()
    other = RolloutBuffer(3, 2, {"x": ((2,), torch.float32)})
    other.load_state_dict(state)  # a resumed run goes on with the rollout it had collected
    assert other.filled == 1 and bool((other.data["x"][0] == 7.0).all())
    with pytest.raises(ValueError):
        RolloutBuffer(4, 2, {"x": ((2,), torch.float32)}).load_state_dict(state)


def test_squashed_gaussian_log_prob_matches_torch_distributions():
    cfg = build_train_config("maac", "tiny", FAST)
    torch.manual_seed(0)
    actor = SquashedGaussianActor(cfg.learner, 3)
    for p in actor.parameters():  # a policy with a wide spread of means and scales
        p.data.normal_(0.0, 0.5)
    obs, mask = torch.randn(4, 3, 3, 8), torch.ones(4, 3, 3, dtype=torch.bool)
    action, logp = actor.sample(obs, mask, torch.Generator().manual_seed(1))
    mean, log_std = actor(obs, mask)
    dist = torch.distributions.TransformedDistribution(
        torch.distributions.Normal(mean, log_std.exp()),
        [torch.distributions.TanhTransform(cache_size=1)],
    )
    expect = dist.log_prob(action.clamp(-1 + 1e-6, 1 - 1e-6)).sum(-1)
    close = action.abs().amax(-1) < 0.999  # atanh is ill-conditioned at the ends
    torch.testing.assert_close(logp[close], expect[close], rtol=1e-3, atol=1e-3)
    assert action.abs().max() <= 1


def test_attention_critic_ignores_dead_pursuers_and_serves_one():
    cfg = build_train_config("maac", "tiny", FAST)
    torch.manual_seed(0)
    critic = AttentionCritic(cfg.learner, 4)
    state, actions = torch.randn(2, 5, 8), torch.rand(2, 4, 2) * 2 - 1
    alive = torch.tensor([[True, True, False, True], [True, False, False, False]])
    state[:, :4] *= alive.unsqueeze(-1)
    q, reg = critic(state, alive, actions)
    assert q.shape == (2, 4) and torch.isfinite(q).all() and reg >= 0
    moved = actions.clone()
    moved[:, 2] = -moved[:, 2]  # a dead pursuer's action changes nothing
    torch.testing.assert_close(critic(state, alive, moved)[0][alive], q[alive])
    moved = actions.clone()
    moved[0, 3] = -moved[0, 3]  # an alive one's changes the others' Q
    assert not torch.allclose(critic(state, alive, moved)[0][0, :2], q[0, :2])
    # the actor's gradient reaches a pursuer's Q through its own action only
    new = actions.clone().requires_grad_(True)
    critic(state, alive, new.detach(), new)[0][0, 0].backward()
    assert new.grad[0, 0].abs().sum() > 0 and new.grad[0, 1:].abs().sum() == 0


def _tiny(algo, out, **values):
    cfg = build_train_config(algo, "tiny", dict(FAST, **values))
    return train(cfg, out, progress=False)


@pytest.mark.parametrize("algo", BASELINES)
def test_baseline_trains_evaluates_and_resumes(algo, tmp_path, capsys):
    run = tmp_path / "run"
    # (the first log row is the demonstrator's under the pes protocol: a second makes
    # best_policy.pt)
    summary = _tiny(algo, run, episodes=24, eval_episodes=4)
    assert summary["updates"] > 0 and summary["eval"]["episodes"] == 4
    ckpt = torch.load(run / "checkpoint.pt", weights_only=True)
    assert ckpt["algo"] == algo and ckpt["progress"]["episodes"] >= 24
    for spec in ("run", "run/policy.pt", "run/checkpoint.pt", "run/best_policy.pt"):
        argv = ["eval", "--policy", str(tmp_path / spec), "--episodes", "2", "--json"]
        assert main([*argv, "--damaged", "1", "--set", "max_steps=20"]) == 0
        assert json.loads(capsys.readouterr().out)["episodes"] == 2
    # resume: the networks and optimisers come back, training goes on
    before = ckpt["progress"]
    cfg = build_train_config(algo, "tiny", dict(FAST, episodes=40, eval_episodes=0))
    after = train(cfg, run, resume=True, progress=False)
    assert after["episodes"] >= 40 and after["updates"] > before["updates"]
    rows = (run / "progress.csv").read_text().splitlines()
    assert sum(r.startswith("episodes") for r in rows) == 1 and len(rows) >= 3
    with pytest.raises(CheckpointError, match="different settings"):
        other = build_train_config(algo, "tiny", dict(FAST, hidden=48, episodes=48))
        train(other, run, resume=True, progress=False)
    # a fixed-size network refuses another swarm size; no model ships under the bare name
    with pytest.raises(CheckpointError, match="sized for 5 pursuers"):
        load_pursuer_policy(run, pes.EnvConfig(num_pursuers=4, capture_count=3))
    assert main(["eval", "--policy", algo, "--episodes", "1"]) == 2
    assert f"no '{algo}' model is shipped" in capsys.readouterr().err


@pytest.mark.parametrize("algo", BASELINES)
def test_per_pursuer_networks_train(algo, tmp_path):
    summary = _tiny(algo, tmp_path / "per", episodes=8, eval_episodes=2, shared=False)
    assert summary["updates"] > 0
    policy, _ = load_pursuer_policy(tmp_path / "per", pes.EnvConfig(max_steps=10))
    assert len(policy.actor.nets.nets) == 5


def test_baseline_config_errors():
    with pytest.raises(ConfigError, match="attention_heads"):
        build_train_config("maac", "tiny", {"hidden": 30, "attention_heads": 4})
    with pytest.raises(ConfigError, match="clip_coef"):
        build_train_config("ppo", "tiny", {"clip_coef": 0.0})
    with pytest.raises(ConfigError, match="rollout_steps"):
        build_train_config("ppo", "tiny", {"rollout_steps": 0})


LEARNING = {
    "ppo": dict(episodes=400, num_envs=16, rollout_steps=32, batch_size=64, hidden=64),
    "mappo": dict(episodes=400, num_envs=16, rollout_steps=32, batch_size=64, hidden=64),
    "maac": dict(episodes=200),
}


@pytest.mark.slow
@pytest.mark.parametrize("algo", BASELINES)
def test_baseline_learns_on_a_tiny_budget(algo, tmp_path):
    """Fixed seed, ~40 s (PPO) / ~65 s (MAAC): see tests/learning.py."""
    assert_learns(algo, tmp_path / "run", log_every=50, **LEARNING[algo])

"""Scripted policies and the evaluation harness."""

from __future__ import annotations

import pytest
import torch

import pes
from pes.evaluate import evaluate
from pes.policies import PIDPotentialField, RandomPolicy


def test_pid_pf_solves_an_easy_map():
    """Heuristic solvability: on an open map against a random evader, PID(PF) captures."""
    cfg = pes.EnvConfig(layout="empty", evader_policy="random", max_steps=300).validate()
    result = evaluate(PIDPotentialField(cfg), cfg, episodes=32, num_envs=32, seed=0)
    assert result.success_rate >= 0.9
    assert result.mean_crashes < 0.2


def test_pid_pf_beats_random_pursuers_on_the_default_map():
    cfg = pes.EnvConfig(crash_mode="disable", max_steps=300).validate()
    pid = evaluate(PIDPotentialField(cfg), cfg, episodes=64, num_envs=64, seed=0)
    rnd = evaluate(RandomPolicy(cfg), cfg, episodes=64, num_envs=64, seed=0)
    assert pid.mean_reward > rnd.mean_reward + 0.1
    assert pid.mean_crashes < 0.5 < rnd.mean_crashes


def test_flee_beats_a_single_pursuer():
    cfg = pes.EnvConfig(
        num_pursuers=1, capture_count=1, max_steps=300, crash_mode="disable"
    ).validate()
    result = evaluate(PIDPotentialField(cfg), cfg, episodes=48, num_envs=48, seed=0)
    assert result.success_rate <= 0.05


def test_evaluation_is_reproducible_and_counts_every_episode():
    cfg = pes.EnvConfig(max_steps=40, disturbance=True).validate()
    a = evaluate(RandomPolicy(cfg), cfg, episodes=10, num_envs=4, seed=3)
    b = evaluate(RandomPolicy(cfg), cfg, episodes=10, num_envs=4, seed=3)
    assert a.episodes == 10 and a.summary() == b.summary()
    assert len(a.per_episode["steps"]) == 10
    assert all(1 <= s <= 40 for s in a.per_episode["steps"])


def test_damaged_evaluation():
    cfg = pes.EnvConfig(max_steps=50, damaged=2, crash_mode="disable").validate()
    result = evaluate(PIDPotentialField(cfg), cfg, episodes=8, num_envs=8, seed=0)
    assert result.episodes == 8


def test_random_policy_is_seeded():
    obs = torch.zeros(3, 5, 5, 8)
    a = RandomPolicy(seed=1)(obs, {})
    b = RandomPolicy(seed=1)(obs, {})
    assert torch.equal(a, b) and a.abs().max() <= 1


def test_evaluate_rejects_zero_episodes():
    from pes.errors import ConfigError

    with pytest.raises(ConfigError):
        evaluate(RandomPolicy(), pes.EnvConfig(), episodes=0)


def test_calibration_cases(monkeypatch):
    """The calibration measures the flee cases, the default DDPG evader and the fully trained
    one's speed ladder, each in its own scenario."""
    from pes.experiments import calibration

    cases = calibration.cases()
    ddpg = [name for name in cases if "DDPG" in name]
    assert ddpg[0] == calibration.PAPER_EVADER_CASE
    assert cases[ddpg[0]][1] == {"evader_policy": "ddpg", "evader_model": "evader-ddpg-paper"}
    assert len(ddpg) == 1 + len(calibration.EVADER_SPEEDS)
    assert cases[ddpg[1]][1] == {
        "evader_policy": "ddpg",
        "evader_model": "evader-ddpg",
        "evader_max_speed": 8.0,
    }
    monkeypatch.setattr(
        calibration, "CASES", {"random, 5 pursuers": calibration.CASES["random, 5 pursuers"]}
    )
    monkeypatch.setattr(calibration, "EVADER_SPEEDS", (9.0,))
    cases = calibration.cases()
    rows = calibration.run(episodes=2, seed=0)
    assert list(rows) == list(cases) and all(r["episodes"] == 2 for r in rows.values())


def test_failures_split_into_a_lost_swarm_and_the_step_limit():
    cfg = pes.EnvConfig(max_steps=60, crash_mode="disable").validate()
    result = evaluate(RandomPolicy(cfg, seed=0), cfg, episodes=24, num_envs=24, seed=0)
    ep = result.per_episode
    assert set(ep["outcome"]) == {"lost", "timeout"}  # random pursuers never capture here
    for outcome, success, steps in zip(ep["outcome"], ep["success"], ep["steps"]):
        assert (outcome == "capture") == success
        assert (outcome == "timeout") == (steps == 60)
    rates = result.success_rate + result.lost_rate + result.timeout_rate
    assert abs(rates - 1.0) < 1e-9 and 0 < result.lost_rate < 1


class _Chase:
    """A row-wise policy: every pursuer heads for the evader (obs row 0, features 6-7); it
    records the batch sizes it is called with."""

    def __init__(self, row_wise: bool) -> None:
        self.row_wise = row_wise
        self.batches: list[int] = []

    def __call__(self, obs, info):
        self.batches.append(obs.shape[0])
        return torch.tanh(obs[:, :, 0, 6:8] * 20.0)

    def reset(self, mask=None) -> None:
        pass


def test_a_row_wise_policy_acts_only_for_the_environments_still_playing():
    """Environments that have played their share step on idle: a row-wise policy is called
    on the others only, and the measured episodes are exactly those of the full batch."""
    cfg = pes.EnvConfig(evader_policy="random", max_steps=60)
    results = {}
    for row_wise in (False, True):
        policy = _Chase(row_wise)
        results[row_wise] = evaluate(policy, cfg, episodes=13, num_envs=4, seed=3)
        assert (min(policy.batches) < 4) == row_wise
    assert results[True].per_episode == results[False].per_episode


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
def test_pid_pf_restored_on_the_cpu_goes_on_on_the_gpu():
    """A checkpoint loads to the CPU: the controller's memory follows the observations to the
    GPU (a demonstrator resumed in a training on CUDA) and it acts as the one it was saved from."""
    env = pes.make_env(num_envs=8, seed=0, device="cuda")
    obs, info = env.reset(seed=0)
    saved = PIDPotentialField()
    for _ in range(5):
        obs, _, _, _, info = env.step(saved(obs, info))
    restored = PIDPotentialField()
    restored.load_state_dict({k: v.cpu() for k, v in saved.state_dict().items()})
    assert torch.allclose(restored(obs, info), saved(obs, info))

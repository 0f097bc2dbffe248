"""The learning check every learner's CI test runs (tests/test_learners.py, test_baselines.py,
test_offpolicy_baselines.py): train on a tiny budget with a fixed seed, then compare the
trained policy with an untrained one of the same architecture."""

from __future__ import annotations

import math
from pathlib import Path

import torch

from pes.algos import ALGOS, build_train_config, train
from pes.algos.loading import load_pursuer_policy
from pes.evaluate import evaluate

FAST = dict(compile_env=False, tensorboard=False)
"""Training options that keep a test run small: no compiled step, no TensorBoard."""

CAPTURE_TASK = dict(
    max_steps=100,
    num_pursuers=3,
    capture_count=1,
    capture_radius=5.0,
    capture_hold=2,
    evader_policy="random",
    dynamics="point_mass",
    layout="empty",
    self_weight=5.0,  # the quick presets' training reward
    cooperation_weight=1.0,
)
"""An identity-style task: one pursuer within 5 m of a randomly moving evader for two steps
captures it, 100-step episodes, no buildings. An untrained swarm hovers and never captures."""


def assert_learns(algo: str, run: Path, protocol: str = "pes", **values) -> None:
    """Train ``algo``'s tiny preset under ``protocol`` on :data:`CAPTURE_TASK` with ``values``
    on top into ``run``; evaluated with the paper's reward over 40 episodes, the trained policy
    must capture at least 20 points more often and earn clearly more reward than an untrained
    one."""
    values = dict(FAST, env=CAPTURE_TASK, eval_episodes=0, **values)
    cfg = build_train_config(algo, "tiny", values, protocol=protocol)
    train(cfg, run, progress=False)
    eval_cfg = cfg.env_config().for_evaluation(disturbance=False)  # the paper's reward
    trained, _ = load_pursuer_policy(run, eval_cfg)
    torch.manual_seed(0)
    untrained, _ = ALGOS[algo].build_policy(cfg, eval_cfg, "cpu")
    good = evaluate(trained, eval_cfg, episodes=40, num_envs=40, seed=123)
    base = evaluate(untrained, eval_cfg, episodes=40, num_envs=40, seed=123)
    assert good.success_rate >= base.success_rate + 0.2, (good.summary(), base.summary())
    assert good.mean_reward > base.mean_reward + 0.1, (good.summary(), base.summary())
    assert math.isfinite(good.mean_steps)

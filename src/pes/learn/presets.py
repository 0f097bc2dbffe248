"""The parts of the budget presets that every method shares, so that a comparison's methods
run on the same budget: the ``quick`` run (a laptop CPU, 60 minutes, 32 environments, the
shipped DDPG evader as opponent) and the ``tiny`` run of the tests (with the protocol's aids
scaled down to its 40 episodes)."""

from __future__ import annotations

from typing import Any

QUICK_RUN: dict[str, Any] = dict(num_envs=32, time_limit=60.0, env=dict(evader_policy="ddpg"))
"""Run keys of every method's ``quick`` preset (its episodes are the method's own)."""

TINY_RUN: dict[str, Any] = dict(
    compile_env=False,  # compiling the step costs more than a tiny run saves by it
    episodes=40,
    num_envs=8,
    log_every=10,
    eval_episodes=20,
    checkpoint_every=0.5,
    env=dict(max_steps=100),
)
"""Run keys of every method's ``tiny`` preset (tests: seconds per run)."""

TINY_PROTOCOL: dict[str, Any] = dict(
    noise=dict(decay_episodes=20), demonstrations=dict(transitions=400)
)
"""The ``tiny`` preset's scaling of the protocol's aids: the noise falls over its first 20
episodes, and the demonstrations fill 400 transitions."""

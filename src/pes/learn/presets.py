"""The parts of the budget presets that every method shares, so that a comparison's methods
run on the same budget: the ``quick`` run (2,000,000 env steps from 32 environments against the
shipped DDPG evader: one to two hours of one CPU thread) and the ``tiny`` run of the tests (with
the protocol's aids scaled down to its 40 episodes)."""

from __future__ import annotations

from typing import Any

QUICK_RUN: dict[str, Any] = dict(
    num_envs=32, env_steps=2_000_000, episodes=10**7, env=dict(evader_policy="ddpg")
)
"""Run keys of every method's ``quick`` preset. Its budget is experience, the same for every
method and on every machine: 2,000,000 env steps (one control step of one environment each;
the episodes do not bind). The learners' settings were searched at half of it (1,000,000 env
steps per trial, results/tuning), where CBC-TP Net's 3 seeds reach 87.8 % and at 2,000,000
92.1 % (results/quick_1m, results/quick). Its hours depend on the method and the CPU: on one
thread of the 2-core machine of results/quick, 79 CPU minutes for MADDPG and 112 for CBC-TP
Net (means of 3 seeds; docs/reproduce.md)."""

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

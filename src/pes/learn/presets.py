"""The parts of the budget presets that every method shares, so that a comparison's methods
run on the same budget: the ``quick`` run (1,000,000 env steps from 32 environments against the
shipped DDPG evader: about an hour of one CPU thread) and the ``tiny`` run of the tests (with the
protocol's aids scaled down to its 40 episodes)."""

from __future__ import annotations

from typing import Any

QUICK_RUN: dict[str, Any] = dict(
    num_envs=32, env_steps=1_000_000, episodes=10**7, env=dict(evader_policy="ddpg")
)
"""Run keys of every method's ``quick`` preset. Its budget is experience, the same for every
method and on every machine: 1,000,000 env steps (one control step of one environment each;
the episodes do not bind). CBC-TP Net's best tuned setting captured 93.0 % of 200 held-out
episodes after 1,000,000 env steps (results/tuning/cbc-tp). Its hours depend on the method and
the CPU: on one thread of the 2-core machine of results/tuning, 47 CPU minutes for MADDPG's
tuned preset and 68 for CBC-TP Net's (docs/reproduce.md)."""

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

"""The parts of the budget presets that every method shares, so that a comparison's methods
run on the same budget: the ``quick`` run (2,000,000 env steps from 32 environments against the
shipped DDPG evader: a laptop CPU's hour or two) and the ``tiny`` run of the tests (with the
protocol's aids scaled down to its 40 episodes)."""

from __future__ import annotations

from typing import Any

QUICK_RUN: dict[str, Any] = dict(
    num_envs=32, env_steps=2_000_000, episodes=10**7, env=dict(evader_policy="ddpg")
)
"""Run keys of every method's ``quick`` preset. Its budget is experience, the same for every
method and on every machine: 2,000,000 env steps (one control step of one environment each;
the episodes do not bind). CBC-TP Net's preset captured 88-92 % of 1000 evaluation episodes
after about 2 M env steps in research/n_step_targets.md (runs y3, v1). Its hours depend on the
method and the CPU: CBC-TP Net's from about 0.9 (the host of run y3) to about 2.5 (2026-12-02)
on one thread (docs/reproduce.md)."""

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

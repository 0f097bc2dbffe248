"""The parts of the budget presets that every method shares, so that a comparison's methods
run on the same budget: the ``quick`` run (2,000,000 env steps from 32 environments against the
shipped DDPG evader: 10 to 90 minutes of one CPU thread, by method), the ``gpu`` run (each
method's quick settings at the sizes of a GPU, :func:`gpu_preset`) and the ``tiny`` run of the
tests (with the protocol's aids scaled down to its 40 episodes)."""

from __future__ import annotations

from typing import Any

from pes.learn.protocol import PES

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

GPU_SCALE = 10
"""The ``gpu`` preset's budget as a multiple of the quick one (20,000,000 env steps)."""
GPU_ENVS = 1024
"""Environments of a replay learner's ``gpu`` preset (stepping on the GPU)."""
GPU_BATCH = 4096
"""Minibatch of a replay learner's ``gpu`` preset."""
GPU_ROLLOUT: dict[str, Any] = dict(num_envs=2048, rollout_steps=64, batch_size=32_768)
"""Rollout of an on-policy learner's ``gpu`` preset: 131,072 transitions in 4 minibatches."""


def gpu_preset(quick: dict[str, Any]) -> dict[str, Any]:
    """A method's ``gpu`` preset: its ``quick`` settings at the sizes that keep a GPU busy.

    * thousands of environments on ``cuda`` (the simulator's compiled step): a replay learner
      :data:`GPU_ENVS`, an on-policy learner :data:`GPU_ROLLOUT`'s rollouts;
    * a replay learner's minibatch is :data:`GPU_BATCH` (TP Net's as many times its quick one),
      and it updates once per ``update_every * GPU_BATCH / batch_size`` env steps, so that each
      env step is replayed as often as in the quick preset; 1,000,000 transitions of replay,
      50,000 of warm-up;
    * :data:`GPU_SCALE` times the quick budget (env steps, or episodes where it has none), and
      the protocol's noise decay and demonstrations stretched alike; no time limit.

    Learning rates and every other setting are the quick preset's. On a machine without a GPU
    it runs with ``--set device=cpu`` (the tests run it so at tiny sizes)."""
    out = dict(quick, device="cuda")
    if "time_limit" in quick:
        out["time_limit"] = 0.0
    if "rollout_steps" in quick:
        out |= GPU_ROLLOUT
    else:
        grow = GPU_BATCH / quick["batch_size"]
        out |= dict(
            num_envs=GPU_ENVS,
            batch_size=GPU_BATCH,
            update_every=round(quick["update_every"] * grow),
            buffer_size=1_000_000,
            warmup=50_000,
        )
        if "tp_batch_size" in quick:
            out["tp_batch_size"] = round(quick["tp_batch_size"] * grow)
    if "env_steps" in quick:
        out["env_steps"] = quick["env_steps"] * GPU_SCALE
    else:
        out["episodes"] = quick["episodes"] * GPU_SCALE
    noise = quick.get("protocol", {}).get("noise", {})
    decay = noise.get("decay_episodes", PES.noise.decay_episodes) * GPU_SCALE
    demos = PES.demonstrations.transitions * GPU_SCALE
    out["protocol"] = dict(
        quick.get("protocol", {}),
        noise=dict(noise, decay_episodes=decay),
        demonstrations=dict(transitions=demos),
    )
    return out

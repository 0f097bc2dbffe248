"""MAPPO (Yu et al., 2022, "The Surprising Effectiveness of PPO in Cooperative Multi-Agent
Games"): PPO with one actor shared by the pursuers on each one's own observation and a
centralised value V(o_i, s) on its observation and the global state (the evader's velocity
included), the agent-specific global state of that paper. It is :class:`pes.algos.ppo.PPO` with
``central_value=True`` and that paper's settings: standardised value targets (ValueNorm), a
Huber value loss, standardised inputs, annealed learning rates, many environments per rollout
and few, large minibatches. Its ``quick`` preset keeps that structure with the learning
settings of PPO's search on this task and the paper's discount (see :data:`MAPPO_QUICK`).
docs/algorithms/mappo.md lists every setting beside that paper's and CleanRL's.
"""

from __future__ import annotations

from typing import Any, ClassVar

from pes.algos.ppo import PPO, PPO_TUNED, STANDARD, PPOConfig
from pes.learn.presets import QUICK_RUN, TINY_PROTOCOL, TINY_RUN, gpu_preset

MAPPO_DEFAULTS: dict[str, Any] = dict(
    central_value=True,
    shared=True,
    gamma=0.99,
    lr_actor=5e-4,
    lr_critic=5e-4,
    hidden=64,
    # Yu et al.'s 0.01 is for the discrete actions of all their benchmarks; on this task's 2-D
    # Gaussian it outweighs the advantages and the policy's spread grows all run (0.69 to 0.93
    # in results/positive_control's first MAPPO trial): CleanRL's continuous-control 0 instead
    ent_coef=0.0,
    grad_clip=10.0,
    huber_delta=10.0,
    ppo_epochs=10,
)
"""Yu et al.'s settings (their Table of common hyper-parameters for MPE and MuJoCo-style
tasks), on top of :class:`PPOConfig`'s defaults, in every preset."""

MAPPO_QUICK: dict[str, Any] = PPO_TUNED | dict(gamma=0.95, grad_clip=1.0, huber_delta=0.0)
"""The learning settings of the quick preset in the place of Yu et al.'s: those of PPO's search
on this task (learning rates 6.12e-4 / 7.8e-4, entropy bonus 1e-3, 128 units), the paper's
discount 0.95, PPO's gradient clip 1 and squared-error value loss. With Yu et al.'s own MAPPO
failed the positive control (results/positive_control: 36.4 % against PID(PF)'s 45.8 % with the
evader at 8 m/s; 43.1 % with the discount 0.95 alone); with these it captured 60.7 % (70.2 % in
an earlier run)."""

MAPPO_PRESETS: dict[str, dict[str, Any]] = {
    "paper": dict(MAPPO_DEFAULTS, episodes=4000, num_envs=1, env=dict(evader_policy="ddpg")),
    # 256 environments x 32 steps = 8,192 transitions (40,960 pursuer samples) per rollout,
    # 4 minibatches of 2,048 transitions, 10 epochs: 244 updates in the quick budget
    "quick": dict(QUICK_RUN, num_envs=256, rollout_steps=32, batch_size=2048)
    | MAPPO_DEFAULTS
    | STANDARD
    | MAPPO_QUICK,
    "tiny": dict(
        TINY_RUN,
        **MAPPO_DEFAULTS | dict(hidden=32, ppo_epochs=4),
        rollout_steps=16,
        batch_size=32,
        bc_epochs=2,
        protocol=TINY_PROTOCOL,
    )
    | STANDARD,
}
MAPPO_PRESETS["gpu"] = gpu_preset(MAPPO_PRESETS["quick"])


class MAPPO(PPO):
    """The MAPPO learner: :class:`PPO` with a centralised value and Yu et al.'s structure."""

    name = "mappo"
    Config = PPOConfig
    PRESETS = MAPPO_PRESETS
    TUNE_SPACE: ClassVar[dict[str, tuple]] = {
        "lr_actor": ("log", 1e-4, 1e-3),
        "lr_critic": ("log", 1e-4, 1e-3),
        "ent_coef": ("choice", [0.0, 1e-3, 1e-2]),
        "gamma": ("choice", [0.95, 0.98, 0.99]),
        "rollout_steps": ("choice", [16, 32, 64]),
        "ppo_epochs": ("choice", [5, 10, 15]),
        "batch_size": ("choice", [1024, 2048, 8192]),
    }

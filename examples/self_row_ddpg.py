"""A learner written outside PES, as docs/algorithms/write_your_own.md shows: DDPG whose actor
sees only each pursuer's own Table I row, with a centralised MLP critic (MADDPG's).

    python examples/self_row_ddpg.py      # trains it on the tiny preset and evaluates it

Inside the package it would be ``src/pes/algos/self_row_ddpg.py`` plus one entry in
``pes.algos.registry.ALGOS``; here it is registered at run time.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from typing import ClassVar

import torch
from torch import Tensor, nn

from pes.algos import ALGOS, build_train_config, train
from pes.algos.maddpg import CentralCritics
from pes.learn.actor_critic import ActorCritic, ActorCriticConfig
from pes.learn.nets import RowScaled, mlp
from pes.learn.presets import TINY_PROTOCOL, TINY_RUN


@dataclass
class SelfRowConfig(ActorCriticConfig):
    """The learner's settings: the actor-critic's (learning rates, buffer, ...) and its own."""

    mlp_hidden: int = 64
    """Units of each hidden layer of the actor's and the critic's MLPs."""
    shared: bool = True
    """One actor for all pursuers (the critic reads this too)."""

    POSITIVE: ClassVar[tuple[str, ...]] = (*ActorCriticConfig.POSITIVE, "mlp_hidden")


class SelfRowActor(RowScaled):
    """Each pursuer's own row (8, scaled) -> MLP -> tanh -> its desired acceleration."""

    def __init__(self, lc: SelfRowConfig) -> None:
        super().__init__(0, lc.obstacle_scale, lc.target_scale)
        self.body = mlp([8, lc.mlp_hidden, lc.mlp_hidden, 2])

    def pre_activation(self, obs: Tensor, mask: Tensor, pred: Tensor | None = None) -> Tensor:
        """obs (B, N, N, 8), mask (B, N, N) -> (B, N, 2) before the tanh."""
        return self.body(obs[:, :, 0] * self.scale)

    def forward(self, obs: Tensor, mask: Tensor, pred: Tensor | None = None) -> Tensor:
        return torch.tanh(self.pre_activation(obs, mask))


class SelfRowDDPG(ActorCritic):
    """The learner: networks only; acting, replay, TD targets and the protocol's aids come from
    :class:`pes.learn.actor_critic.ActorCritic`."""

    name = "self-row-ddpg"
    Config = SelfRowConfig
    PRESETS: ClassVar[dict] = {
        "tiny": dict(
            TINY_RUN,
            mlp_hidden=32,
            buffer_size=20_000,
            batch_size=64,
            update_every=8,
            warmup=500,
            protocol=TINY_PROTOCOL,
        )
    }

    @staticmethod
    def make_actor(lc: SelfRowConfig, num_pursuers: int) -> nn.Module:
        return SelfRowActor(lc)

    @staticmethod
    def make_critic(lc: SelfRowConfig, num_pursuers: int) -> nn.Module:
        return CentralCritics(lc, num_pursuers)


def main() -> None:
    ALGOS[SelfRowDDPG.name] = SelfRowDDPG  # in the package: one line in pes.algos.registry
    cfg = build_train_config(
        "self-row-ddpg", "tiny", {"episodes": 20, "eval_episodes": 10, "compile_env": False}
    )
    with tempfile.TemporaryDirectory() as out:
        summary = train(cfg, out, progress=False)
    print(f"{summary['episodes']} episodes, {summary['updates']} updates; aids: {summary['aids']}")
    print(f"evaluation: {summary['eval']['success_rate']:.2f} success over 10 episodes")


if __name__ == "__main__":
    main()

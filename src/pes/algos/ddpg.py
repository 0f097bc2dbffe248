"""DDPG (Lillicrap et al., 2016) as independent learners: each pursuer acts on its own observation
and is judged by a critic that sees only that observation and its own action.

It is :class:`pes.algos.maddpg.MADDPG` with decentralised critics (a variant of that baseline,
so a subclass): the same settings (but ``shared``'s default), presets, MLP actors, replay
storage, update and target networks; critic i reads pursuer i's Table I observation (N rows of
8, scaled, with their real-row flags) and its action instead of the global state and every
action. The other pursuers are part of each learner's environment, so its Q is non-stationary
while they learn -- the weakness MADDPG's centralised critics address.

``shared=True`` (the default) gives one actor and one critic trained on every pursuer's
experience (parameter sharing, as PPO's and MAAC's pursuers share theirs); ``shared=False`` one
of each per pursuer. Damaged pursuers: their rows are zero and flagged 0 in the others'
observations, and their own Qs are left out of the losses.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from pes.algos.maddpg import DDPG_PRESETS, MADDPG, MADDPGConfig
from pes.learn.features import pursuer_obs
from pes.learn.nets import EnsembleMLP, RowScaled, observation_input


class LocalCritics(RowScaled):
    """Critic i: pursuer i's observation (9N numbers, as :class:`pes.algos.maddpg.MLPActors`)
    and its own action (2) -> MLP (two hidden layers of ``mlp_hidden``) -> Q_i."""

    def __init__(self, lc: MADDPGConfig, num_pursuers: int) -> None:
        super().__init__(0, lc.obstacle_scale, lc.target_scale)
        self.n = num_pursuers
        members = 1 if lc.shared else num_pursuers
        h = lc.mlp_hidden
        self.body = EnsembleMLP(members, [9 * num_pursuers + 2, h, h, 1])

    def each(self, state: Tensor, alive: Tensor, actions: Tensor) -> Tensor:
        """state (B, A, 8), alive (B, N), actions (N, B, N, 2) (row i: critic i's joint action,
        of which it reads only a_i) -> Q (B, N)."""
        obs, mask = pursuer_obs(state, alive)
        agents = torch.arange(self.n, device=state.device)
        own = actions[agents, :, agents]  # (N, B, 2)
        x = torch.cat([observation_input(obs, mask, self.scale), own], dim=-1)
        return self.body(x).squeeze(-1).transpose(0, 1)

    def forward(
        self, state: Tensor, alive: Tensor, actions: Tensor, pred: Tensor | None = None
    ) -> Tensor:
        """state (B, A, 8), alive (B, N), actions (B, N, 2) -> Q (B, N)."""
        return self.each(state, alive, actions.unsqueeze(0).expand(self.n, *actions.shape))


@dataclass
class DDPGConfig(MADDPGConfig):
    """DDPG's settings: MADDPG's, with parameter sharing by default."""

    shared: bool = True
    """One actor and one critic for all pursuers, trained on every pursuer's experience; False:
    one each. With one each, a learner gets a fifth of the experience (five pursuers) and
    failed the positive control (docs/algorithms/ddpg.md)."""


class DDPG(MADDPG):
    """Independent DDPG learners (``algo: ddpg``)."""

    name = "ddpg"
    Config = DDPGConfig
    PRESETS = DDPG_PRESETS

    @staticmethod
    def make_critic(lc: MADDPGConfig, num_pursuers: int) -> nn.Module:
        return LocalCritics(lc, num_pursuers)

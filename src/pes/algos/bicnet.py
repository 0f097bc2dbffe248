"""BiCNet (Peng et al., 2017, "Multiagent Bidirectionally-Coordinated Nets"): one bidirectional
RNN runs across the pursuers, in index order, in both the actor and the critic; each agent's
cell outputs its own action (actor) or its own Q (critic), and the RNN's hidden states are the
agents' communication channel.

It trains on CBC-TP's machinery (:class:`pes.algos.cbc_tp.CBCTP`) with ``use_tp=False`` and
``actor_gradient="all"``: BiCNet's actor gradient sums over every agent's Q the gradients through
every agent's action, all of which come from the one actor (eq. 8 of Peng et al.). The critic is
CBC-TP's (:class:`pes.algos.nets.CBCCritic` without a prediction), which is BiCNet's: a
bidirectional LSTM across the pursuers, cell j holding pursuer j's global-state row, the
evader's row, j's action and an alive flag. What differs from CBC Net is the actor: BiCNet's
crosses the team once for all agents (cell j: pursuer j's own observation row) instead of
crossing each pursuer's observation with the pursuer itself at both ends.

Damaged pursuers keep their place in the sequence with a zero row and a 0 flag, their actions
are ignored (the environment stops them; the critic zeroes them) and their Qs are left out of
the losses. The networks serve any number of pursuers.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from pes.algos.cbc_tp import CBCTP, PursuerCritics
from pes.algos.config import TrainConfig
from pes.algos.nets import RowScaled, mlp
from pes.errors import ConfigError
from pes.sim.config import EnvConfig


class BiCNetActor(RowScaled):
    """BiCNet's actor: a bidirectional LSTM (``hidden`` per direction) across the pursuers, cell
    j holding pursuer j's own observation row (Table I self row, 8, scaled as CBC-TP's) and its
    alive flag; each cell's output -> MLP (``mlp_hidden``, ReLU) -> tanh -> pursuer j's desired
    acceleration. The last layer starts within +-3e-3, as CBC-TP's."""

    def __init__(self, cfg: TrainConfig) -> None:
        super().__init__(0, cfg.obstacle_scale, cfg.target_scale)
        self.lstm = nn.LSTM(9, cfg.hidden, batch_first=True, bidirectional=True)
        self.head = mlp([2 * cfg.hidden, cfg.mlp_hidden, 2])
        nn.init.uniform_(self.head[-1].weight, -3e-3, 3e-3)
        nn.init.uniform_(self.head[-1].bias, -3e-3, 3e-3)

    def pre_activation(self, obs: Tensor, mask: Tensor, pred: Tensor | None = None) -> Tensor:
        """obs (B, N, N, 8), mask (B, N, N) -> (B, N, 2) before the tanh (only each pursuer's
        own row, ``obs[:, j, 0]``, is read; ``pred`` is unused)."""
        own, alive = obs[:, :, 0], mask[:, :, 0]
        cells = torch.cat([own * self.scale, alive.unsqueeze(-1).to(obs.dtype)], dim=-1)
        out, _ = self.lstm(cells)
        return self.head(out)

    def forward(self, obs: Tensor, mask: Tensor, pred: Tensor | None = None) -> Tensor:
        """obs (B, N, N, 8), mask (B, N, N) -> actions (B, N, 2) in [-1, 1]."""
        return torch.tanh(self.pre_activation(obs, mask))


class BiCNet(CBCTP):
    """The BiCNet learner (``algo: bicnet``)."""

    name = "bicnet"

    def __init__(self, cfg: TrainConfig, env_cfg: EnvConfig, device: torch.device) -> None:
        if cfg.use_tp:
            raise ConfigError("bicnet has no TP Net: set use_tp=false")
        if not cfg.shared:
            raise ConfigError("bicnet's networks span all pursuers: shared must be true")
        if cfg.actor_gradient != "all":
            raise ConfigError("bicnet's actor acts for every pursuer: actor_gradient must be all")
        super().__init__(cfg, env_cfg, device)

    @staticmethod
    def make_actor(cfg: TrainConfig, num_pursuers: int) -> nn.Module:
        return BiCNetActor(cfg)

    @staticmethod
    def make_critic(cfg: TrainConfig, num_pursuers: int) -> nn.Module:
        return PursuerCritics(cfg, num_pursuers)

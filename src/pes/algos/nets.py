"""The networks of CBC-TP Net (Fig. 3-4, Table II), of the DDPG evader, and the pieces the
baselines share (a flat-observation MLP, per-agent or shared networks).

Shapes use E or B for a batch, N pursuers, A = N + 1 vehicles, k predicted steps, n history
steps. Positions are in arena units (metres / arena size), as in the observations.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from pes.algos.features import relative_prediction


def mlp(sizes: list[int], out_act: nn.Module | None = None) -> nn.Sequential:
    """Linear layers with ReLU between them (and ``out_act`` after the last one)."""
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(nn.ReLU())
    if out_act is not None:
        layers.append(out_act)
    return nn.Sequential(*layers)


class TPNet(nn.Module):
    """Target prediction (Fig. 3, eq. 7): an LSTM over the last n frames that predicts the
    evader's next k positions.

    Each frame is summarised so that one network serves any number of pursuers: the evader's
    [position, velocity] and, relative to it, the mean [position, velocity] of the alive
    pursuers and the nearest alive pursuer's (12 numbers). The LSTM's last output goes through
    a linear layer to k displacements from the evader's current position.
    """

    FRAME_FEATURES = 12

    def __init__(self, hidden: int = 256, layers: int = 2, horizon: int = 3) -> None:
        super().__init__()
        self.horizon = horizon
        self.lstm = nn.LSTM(self.FRAME_FEATURES, hidden, num_layers=layers, batch_first=True)
        self.head = nn.Linear(hidden, 2 * horizon)

    @staticmethod
    def summarise(frames: Tensor) -> Tensor:
        """(..., n, A, 4) history frames -> (..., n, 12) frame features."""
        evader = frames[..., -1, :]
        rel = frames[..., :-1, :] - evader.unsqueeze(-2)
        present = frames[..., :-1, :].abs().sum(-1) > 0  # dead pursuers and padding are zero
        w = present.unsqueeze(-1).to(frames.dtype)
        mean = (rel * w).sum(-2) / w.sum(-2).clamp(min=1.0)
        gap = (rel[..., :2] ** 2).sum(-1).masked_fill(~present, float("inf"))
        nearest = gap.argmin(-1, keepdim=True)
        near = rel.gather(-2, nearest.unsqueeze(-1).expand(*nearest.shape, 4)).squeeze(-2)
        near = near * present.any(-1, keepdim=True).to(frames.dtype)
        return torch.cat([evader, mean, near], dim=-1)

    def forward(self, frames: Tensor) -> Tensor:
        """(B, n, A, 4) history frames, oldest first -> (B, k, 2) predicted evader positions."""
        out, _ = self.lstm(self.summarise(frames))
        disp = self.head(out[:, -1]).view(-1, self.horizon, 2)
        return frames[:, -1, -1, :2].unsqueeze(1) + disp


class RowScaled(nn.Module):
    """Base of the CBC actor and critic: the factors applied to the columns of a Table I row
    before a network sees it (a buffer, so that they travel with the weights).

    The rows are in arena units (metres / arena size), where the 2 m safety margin of eq. (9) is
    0.02 and the 2 m capture radius too: the networks would need weights of ~100 to resolve
    them. The obstacle vector (columns 4-5) is multiplied by ``obstacle_scale`` and the vector
    to the evader (columns 6-7) and the relative prediction (``pred_dim`` numbers) by
    ``target_scale``; positions and velocities are kept."""

    def __init__(self, pred_dim: int, obstacle_scale: float, target_scale: float) -> None:
        super().__init__()
        self.pred_dim = pred_dim
        self.target_scale = target_scale
        factors = [1.0, 1.0, 1.0, 1.0] + [obstacle_scale] * 2 + [target_scale] * 2
        self.register_buffer("scale", torch.tensor(factors))


class CBCActor(RowScaled):
    """The CBC actor (Fig. 4a): a bidirectional LSTM across the agents of one pursuer's
    observation, with the pursuer itself at the first and the last cell, joined with the
    predicted evader path (relative to the pursuer) and an MLP to the desired acceleration.

    Each cell's input is the observation row (8, scaled by :class:`RowScaled`) and a 1/0 flag
    saying whether the row is real; masked rows are zero, so any number of alive pursuers goes
    through the same network. The last layer starts near zero (as DDPG's), so that the untrained
    swarm hovers instead of flying into the nearest wall.
    """

    def __init__(
        self,
        hidden: int = 256,
        mlp_hidden: int = 64,
        pred_dim: int = 6,
        obstacle_scale: float = 1.0,
        target_scale: float = 1.0,
    ) -> None:
        super().__init__(pred_dim, obstacle_scale, target_scale)
        self.hidden = hidden
        self.lstm = nn.LSTM(9, hidden, batch_first=True, bidirectional=True)
        self.head = mlp([2 * hidden + pred_dim, mlp_hidden, 2])
        nn.init.uniform_(self.head[-1].weight, -3e-3, 3e-3)
        nn.init.uniform_(self.head[-1].bias, -3e-3, 3e-3)

    def pre_activation(self, obs: Tensor, mask: Tensor, pred: Tensor | None) -> Tensor:
        """obs (B, N, 8), mask (B, N), pred (B, pred_dim) or None -> (B, 2) before the tanh."""
        cells = torch.cat([obs * self.scale, mask.unsqueeze(-1).to(obs.dtype)], dim=-1)
        seq = torch.cat([cells, cells[:, :1]], dim=1)  # self first and last
        out, _ = self.lstm(seq)
        h = self.hidden
        feat = torch.cat([out[:, -1, :h], out[:, 0, h:]], dim=-1)
        if self.pred_dim:
            feat = torch.cat([feat, pred * self.target_scale], dim=-1)
        return self.head(feat)

    def forward(self, obs: Tensor, mask: Tensor, pred: Tensor | None) -> Tensor:
        """obs (B, N, 8), mask (B, N), pred (B, pred_dim) or None -> actions (B, 2) in [-1, 1]."""
        return torch.tanh(self.pre_activation(obs, mask, pred))


class CBCCritic(RowScaled):
    """The centralised critic (Fig. 4b): a bidirectional LSTM across all pursuers, each cell
    holding that pursuer's global-state row (8), the evader's [position, velocity, obstacle
    vector] (6), its action (2), the predicted evader path relative to it (2k) and an alive
    flag; an MLP (64) on each cell's output gives that pursuer's Q. Rows are scaled as the
    actor's (:class:`RowScaled`)."""

    def __init__(
        self,
        hidden: int = 256,
        mlp_hidden: int = 64,
        pred_dim: int = 6,
        obstacle_scale: float = 1.0,
        target_scale: float = 1.0,
    ) -> None:
        super().__init__(pred_dim, obstacle_scale, target_scale)
        self.lstm = nn.LSTM(8 + 6 + 2 + pred_dim + 1, hidden, batch_first=True, bidirectional=True)
        self.head = mlp([2 * hidden, mlp_hidden, 1])

    def forward(self, state: Tensor, alive: Tensor, actions: Tensor, pred: Tensor | None) -> Tensor:
        """state (B, A, 8), alive (B, N), actions (B, N, 2), pred (B, k, 2) -> Q (B, N)."""
        n = alive.shape[-1]
        state = state * self.scale
        evader = state[:, -1:, :6].expand(-1, n, -1)
        parts = [state[:, :n], evader, actions * alive.unsqueeze(-1)]
        if self.pred_dim:
            rel = relative_prediction(pred, state, n) * self.target_scale
            parts.append(rel * alive.unsqueeze(-1))
        parts.append(alive.unsqueeze(-1).to(state.dtype))
        out, _ = self.lstm(torch.cat(parts, dim=-1))
        return self.head(out).squeeze(-1)


class DeepSetActor(nn.Module):
    """The DDPG evader's actor: its own row, plus the max and mean of an embedding of each alive
    pursuer's row (so it plays against any number of pursuers), through an MLP to its action.

    Input: ``info["evader_obs"]`` (B, A, 8) as built by :func:`pes.sim.scenario.observe`."""

    def __init__(self, hidden: int = 128, action_dim: int = 0) -> None:
        super().__init__()
        self.embed = mlp([8, hidden, hidden], nn.ReLU())
        self.head = mlp([8 + action_dim + 2 * hidden, hidden, hidden, 1 if action_dim else 2])
        self.squash = nn.Identity() if action_dim else nn.Tanh()

    def features(self, obs: Tensor) -> Tensor:
        others = obs[:, 1:]
        present = (others.abs().sum(-1) > 0).unsqueeze(-1)
        emb = self.embed(others)
        w = present.to(obs.dtype)
        mean = (emb * w).sum(1) / w.sum(1).clamp(min=1.0)
        top = emb.masked_fill(~present, 0.0).amax(1)  # embeddings are >= 0 (ReLU)
        return torch.cat([mean, top], dim=-1)

    def forward(self, obs: Tensor, action: Tensor | None = None) -> Tensor:
        """obs (B, A, 8) -> action (B, 2) in [-1, 1]; with ``action`` (critic) -> Q (B,)."""
        parts = [obs[:, 0]] + ([action] if action is not None else []) + [self.features(obs)]
        out = self.squash(self.head(torch.cat(parts, dim=-1)))
        return out.squeeze(-1) if action is not None else out


class DeepSetCritic(DeepSetActor):
    """The DDPG evader's critic: :class:`DeepSetActor`'s body with the action beside its own
    row, giving Q (B,)."""

    def __init__(self, hidden: int = 128) -> None:
        super().__init__(hidden, action_dim=2)


class FlatObsMLP(RowScaled):
    """An MLP on one pursuer's whole observation, for the baselines built for a fixed swarm
    size (PPO, MAAC): its N Table I rows, scaled as :class:`RowScaled`, each followed by its
    real-row flag, flattened to 9N inputs, then ``layers`` hidden ReLU layers of ``hidden`` units
    and a linear output. Masked (dead) rows are zero with a 0 flag.

    The last layer starts within ±3e-3 (as DDPG's actor), so that an untrained policy's mean
    action is near zero.
    """

    def __init__(
        self,
        num_pursuers: int,
        hidden: int,
        out_dim: int,
        layers: int = 2,
        obstacle_scale: float = 1.0,
        target_scale: float = 1.0,
    ) -> None:
        super().__init__(0, obstacle_scale, target_scale)
        self.num_pursuers = num_pursuers
        self.body = mlp([9 * num_pursuers] + [hidden] * layers + [out_dim])
        nn.init.uniform_(self.body[-1].weight, -3e-3, 3e-3)
        nn.init.uniform_(self.body[-1].bias, -3e-3, 3e-3)

    def forward(self, obs: Tensor, mask: Tensor) -> Tensor:
        """obs (B, N, 8), mask (B, N) -> (B, out_dim)."""
        cells = torch.cat([obs * self.scale, mask.unsqueeze(-1).to(obs.dtype)], dim=-1)
        return self.body(cells.flatten(-2))


class PerAgent(nn.Module):
    """One network shared by all pursuers (``shared=True``) or one network per pursuer, applied
    along dimension 1 of its inputs: every input is (B, N, ...), the output (B, N, ...).

    ``make()`` builds one network; with sharing it is called once, otherwise N times.
    """

    def __init__(self, make, num_agents: int, shared: bool) -> None:
        super().__init__()
        self.nets = nn.ModuleList(make() for _ in range(1 if shared else num_agents))

    def forward(self, *inputs: Tensor) -> Tensor:
        """inputs each (B, N, ...) -> (B, N, ...)."""
        if len(self.nets) == 1:
            b, n = inputs[0].shape[:2]
            out = self.nets[0](*(x.flatten(0, 1) for x in inputs))
            return out.view(b, n, *out.shape[1:])
        return torch.stack(
            [net(*(x[:, i] for x in inputs)) for i, net in enumerate(self.nets)], dim=1
        )

"""Network building blocks that the learners share: MLPs, the input scaling of Table I rows,
flat-observation MLPs, per-agent or shared networks, and ensembles of independent MLPs.

Shapes use E or B for a batch, N pursuers, A = N + 1 vehicles, k predicted steps, n history
steps. Positions are in arena units (metres / arena size), as in the observations.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn


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


class _SigmoidTanh(torch.autograd.Function):
    """tanh(x) = 2 sigmoid(2x) - 1, with tanh's own backward from the saved output."""

    @staticmethod
    def forward(ctx, x: Tensor) -> Tensor:
        y = torch.sigmoid(2.0 * x).mul_(2.0).sub_(1.0)
        ctx.save_for_backward(y)
        return y

    @staticmethod
    def backward(ctx, grad: Tensor) -> Tensor:
        (y,) = ctx.saved_tensors
        return torch.ops.aten.tanh_backward(grad, y)


class Tanh(nn.Module):
    """The tanh activation, computed on a CPU as 2 sigmoid(2x) - 1 (the same function to
    float rounding, ~2e-7): torch's CPU tanh kernel takes 4x the time of its sigmoid, and a
    tanh MLP's activations are a fifth of its update there (benchmarks/bench_train.py). On other
    devices it is ``torch.tanh``."""

    def forward(self, x: Tensor) -> Tensor:
        if x.device.type != "cpu":
            return torch.tanh(x)
        return _SigmoidTanh.apply(x)


class RowScaled(nn.Module):
    """Base of the networks that read Table I rows: the factors applied to a row's columns
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


class EnsembleLinear(nn.Module):
    """``members`` independent linear layers applied at once: (K, B, in) -> (K, B, out),
    each initialised as :class:`torch.nn.Linear`."""

    def __init__(self, members: int, fan_in: int, fan_out: int) -> None:
        super().__init__()
        bound = 1.0 / math.sqrt(fan_in)
        self.weight = nn.Parameter(torch.empty(members, fan_in, fan_out).uniform_(-bound, bound))
        self.bias = nn.Parameter(torch.empty(members, 1, fan_out).uniform_(-bound, bound))

    def forward(self, x: Tensor) -> Tensor:
        return torch.bmm(x, self.weight) + self.bias  # 2x faster than baddbmm's broadcast bias


class EnsembleMLP(nn.Module):
    """``members`` MLPs of the same ``sizes`` (ReLU between layers), one per agent or one shared
    by all (``members == 1``). Input (N, B, in) -> (N, B, out); a single member is applied to
    every agent's slice. The last layer starts within +-3e-3 when ``small_out`` (DDPG's init)."""

    def __init__(self, members: int, sizes: list[int], small_out: bool = False) -> None:
        super().__init__()
        self.layers = nn.ModuleList(
            EnsembleLinear(members, sizes[i], sizes[i + 1]) for i in range(len(sizes) - 1)
        )
        if small_out:
            nn.init.uniform_(self.layers[-1].weight, -3e-3, 3e-3)
            nn.init.uniform_(self.layers[-1].bias, -3e-3, 3e-3)

    @property
    def members(self) -> int:
        return self.layers[0].weight.shape[0]

    def forward(self, x: Tensor) -> Tensor:
        k, b = x.shape[:2]
        if self.members == 1:
            x = x.reshape(1, k * b, -1)
        for i, layer in enumerate(self.layers):
            x = layer(x)
            if i < len(self.layers) - 1:
                x = torch.relu(x)
        return x.reshape(k, b, -1)


def observation_input(obs: Tensor, mask: Tensor, scale: Tensor) -> Tensor:
    """Each pursuer's flat MLP input: obs (B, N, N, 8) scaled by ``scale`` (8,) and its row
    flags mask (B, N, N) -> (N, B, 9N), agent-major for :class:`EnsembleMLP`."""
    rows = torch.cat([obs * scale, mask.unsqueeze(-1).to(obs.dtype)], dim=-1)
    return rows.flatten(-2).transpose(0, 1)

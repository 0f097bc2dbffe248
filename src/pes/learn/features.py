"""What the learners see, rebuilt from the global state that the replay buffer stores.

The buffer keeps one global state per transition (docs/scenario.md, "Observations"): (A, 8) rows,
pursuers first (their Table I self rows, zero when dead) and the evader last. Every pursuer's
observation, the history windows of TP Net and the inputs of the critic are functions of it, so
they are recomputed for each sampled minibatch instead of being stored N times.
"""

from __future__ import annotations

import torch
from torch import Tensor


def other_index(num_pursuers: int, device: torch.device | str = "cpu") -> Tensor:
    """(N, N) long: row k of pursuer i's observation shows pursuer ``other_index[i, k]`` (itself
    first, then the others in increasing order), as in :func:`pes.sim.scenario.observe`."""
    n = num_pursuers
    rows = [[i] + [j for j in range(n) if j != i] for i in range(n)]
    return torch.tensor(rows, dtype=torch.long, device=device)


def pursuer_obs(state: Tensor, alive: Tensor) -> tuple[Tensor, Tensor]:
    """Every pursuer's Table I observation from the global state.

    Args:
        state: (..., N + 1, 8) global states (``info["state"]``).
        alive: (..., N) bool.

    Returns:
        obs (..., N, N, 8) and its row mask (..., N, N), equal to the environment's ``obs`` and
        ``info["obs_mask"]``.
    """
    n = alive.shape[-1]
    idx = other_index(n, state.device)
    rows = state[..., :n, :]
    picked = rows.index_select(-2, idx.flatten()).unflatten(-2, (n, n))  # (..., N, N, 8)
    # the others' rows relative to the pursuer's own position and velocity (columns 0-3);
    # its own row (k = 0) and the obstacle and evader vectors (columns 4-7) stay as they are
    offset = torch.ones(n, 8, dtype=state.dtype, device=state.device)
    offset[0] = 0.0
    offset[:, 4:] = 0.0
    obs = picked - rows.unsqueeze(-2) * offset
    mask = alive.index_select(-1, idx.flatten()).unflatten(-1, (n, n)) & alive.unsqueeze(-1)
    return obs * mask.unsqueeze(-1), mask


def frames(state: Tensor) -> Tensor:
    """History frames (..., N + 1, 4): normalised [position, velocity] of every vehicle, the
    same numbers as one frame of ``info["history"]``."""
    return state[..., :4]


def relative_prediction(pred: Tensor, state: Tensor, num_pursuers: int) -> Tensor:
    """TP Net's predicted evader positions as seen from each pursuer.

    Args:
        pred: (..., k, 2) predicted normalised evader positions.
        state: (..., N + 1, 8).

    Returns:
        (..., N, 2k): for pursuer j, ``pred - position_j`` flattened (the 1x6 input of Fig. 4
        for k = 3), zero for dead pursuers (whose state rows are zero) only through their
        masks downstream.
    """
    pos = state[..., :num_pursuers, :2]  # (..., N, 2)
    rel = pred.unsqueeze(-3) - pos.unsqueeze(-2)  # (..., N, k, 2)
    return rel.flatten(-2)

"""The interface every pursuer policy implements."""

from __future__ import annotations

from typing import Protocol

from torch import Tensor


class Policy(Protocol):
    """Maps a batch of observations to a batch of actions.

    ``__call__(obs, info)``: ``obs`` (E, N, N, 8) and ``info`` as returned by the environment's
    ``reset``/``step`` (``info["obs_mask"]`` marks the real rows); returns (E, N, 2) actions in
    [-1, 1]. ``reset(mask)``: forget what was remembered for the environments where ``mask``
    (E,) is true (all of them when ``mask`` is None), because a new episode starts there.
    """

    def __call__(self, obs: Tensor, info: dict[str, Tensor]) -> Tensor: ...

    def reset(self, mask: Tensor | None = None) -> None: ...

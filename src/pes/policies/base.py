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

    A policy may set ``row_wise = True`` when environment ``i``'s actions depend on row ``i``
    of ``obs`` and ``info`` alone and it keeps no state between calls: the evaluation harness
    then calls it on the environments that are still playing only.
    """

    def __call__(self, obs: Tensor, info: dict[str, Tensor]) -> Tensor: ...

    def reset(self, mask: Tensor | None = None) -> None: ...

"""A counter-based random number generator in plain tensor arithmetic.

Every random number in the simulator is a hash of integers that name it: the environment's
key, the episode, the step, a stream (what the number is for) and an index (which vehicle,
which coordinate). This makes the step a pure function of (state, actions) -- no generator
object, nothing for ``torch.compile`` to break on, the same numbers on CPU and CUDA -- and
makes each environment's randomness independent of how many environments run beside it:
environment ``i`` of a batch reset with seed ``s`` sees exactly the numbers of a single
environment reset with seed ``s + i`` (the Gymnasium vector convention).

Keys are derived per environment with :func:`derive` (cheap: one number per environment),
then :func:`uniform` draws the numbers of many indices from a key. The mixer is the 32-bit
"lowbias32" finaliser with multipliers below 2**31, in int64 so that no product overflows.
Each stage of the mixer reads its input twice, so a compiled expression grows twofold per
stage: keep chains short (the simulator stores each episode's key and derives from it at
most twice per draw).
"""

from __future__ import annotations

import torch
from torch import Tensor

_MASK = 0xFFFFFFFF
_GOLDEN = 0x9E3779B9


def mix32(x: Tensor) -> Tensor:
    """Hash an int64 tensor to well-mixed values in [0, 2**32)."""
    x = x & _MASK
    x = x ^ (x >> 16)
    x = (x * 0x7FEB352D) & _MASK
    x = x ^ (x >> 15)
    x = (x * 0x5BD1E995) & _MASK
    return x ^ (x >> 16)


def derive(key: Tensor, part: Tensor | int) -> Tensor:
    """A new key from ``key`` and an integer ``part`` (a tensor broadcast with ``key``)."""
    return mix32(key ^ ((part * _GOLDEN) & _MASK))


def uniform(key: Tensor, index: Tensor | int, dtype: torch.dtype = torch.float32) -> Tensor:
    """Uniform numbers in [0, 1) for the ``index``-th draws of ``key`` (broadcast together)."""
    return (derive(key, index) >> 8).to(dtype) * (1.0 / (1 << 24))


def env_keys(seed: int, num_envs: int, device: torch.device | str = "cpu") -> Tensor:
    """Per-environment keys (num_envs,) int64: environment ``i`` is keyed by ``seed + i``."""
    ids = torch.arange(num_envs, dtype=torch.int64, device=device) + int(seed)
    return mix32(mix32(ids & _MASK) ^ ((ids >> 32) & _MASK))

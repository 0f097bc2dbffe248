"""Uniformly random pursuers: the untrained baseline every learner must beat."""

from __future__ import annotations

import torch
from torch import Tensor


class RandomPolicy:
    """Actions drawn uniformly from [-1, 1]^2 for every pursuer, from a seeded generator."""

    def __init__(self, config=None, seed: int = 0) -> None:
        self.seed = seed
        self.generator: torch.Generator | None = None

    def __call__(self, obs: Tensor, info: dict[str, Tensor]) -> Tensor:
        if self.generator is None or self.generator.device != obs.device:
            self.generator = torch.Generator(device=obs.device).manual_seed(self.seed)
        shape = (obs.shape[0], obs.shape[1], 2)
        return torch.rand(shape, generator=self.generator, device=obs.device) * 2.0 - 1.0

    def reset(self, mask: Tensor | None = None) -> None:
        """Stateless: nothing to forget."""

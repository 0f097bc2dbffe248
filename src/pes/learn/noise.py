"""Exploration noise processes, batched over environments and agents."""

from __future__ import annotations

import torch
from torch import Tensor


class OUNoise:
    """Ornstein-Uhlenbeck noise (Algorithm 1, line 5): per step
    ``x += theta * (mu - x) * dt + sigma * sqrt(dt) * N(0, 1)``, one process per entry of
    ``shape`` (e.g. (num_envs, N, 2)); :meth:`reset` restarts the processes of finished
    environments at ``mu``."""

    def __init__(
        self,
        shape: tuple[int, ...],
        theta: float = 0.15,
        sigma: float = 0.2,
        dt: float = 1.0,
        mu: float = 0.0,
        device: torch.device | str = "cpu",
    ) -> None:
        self.theta, self.sigma, self.dt, self.mu = theta, sigma, dt, mu
        self.x = torch.full(shape, mu, device=device)

    def sample(self, generator: torch.Generator | None = None, scale: float = 1.0) -> Tensor:
        """Advance every process one step and return the noise, scaled by ``scale``."""
        eps = torch.randn(self.x.shape, generator=generator).to(self.x.device)
        self.x += self.theta * (self.mu - self.x) * self.dt + self.sigma * self.dt**0.5 * eps
        return self.x * scale

    def reset(self, mask: Tensor | None = None) -> None:
        """Restart the processes of environments where ``mask`` (num_envs,) is true (all if
        None)."""
        if mask is None:
            self.x.fill_(self.mu)
        else:
            self.x[mask.to(self.x.device)] = self.mu

    def state_dict(self) -> dict:
        return {"x": self.x.clone()}

    def load_state_dict(self, state: dict) -> None:
        self.x.copy_(state["x"])

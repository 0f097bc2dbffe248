"""The evader's behaviours. The evader is part of the scenario: the environment runs its
configured policy inside the step (``EnvConfig.evader_policy``).

Every policy is a callable ``policy(vehicles, counters, flags) -> (ax, ay)`` over the
simulator's state (see :mod:`pes.sim.scenario`) returning the evader's action as two (E,)
tensors in [-1, 1]: a desired acceleration as a fraction of the evader's maximum.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
from torch import Tensor

from pes.errors import ConfigError
from pes.sim import kernels, rng
from pes.sim.dynamics import Vehicles
from pes.sim.geometry import ray_distance

EvaderPolicy = Callable[..., tuple[Tensor, Tensor]]

STREAM_EVADER_RANDOM = 5  # see the streams in pes.sim.scenario


class FleeEvader:
    """Scripted evader: flee from the pursuers' weighted positions, repelled by obstacles,
    without running into a corner.

    The "away" vector sums unit vectors from each alive pursuer to the evader, weighted by
    (threat_radius / d)^2 (the nearest pursuers count most, far ones barely), plus a push from
    the nearest obstacle within ``wall_influence``. Along each of ``num_rays`` headings the
    evader can fly ``free`` metres before coming within ``margin`` of a building or wall (a ray
    cast, capped at ``lookahead``). Each heading scores its agreement with "away", the open
    space ahead, and -- so that dead ends and corners score low -- how far the end of its free
    segment lies from the nearest pursuer extrapolated to the time the evader gets there. The
    evader flies the best heading at full speed, braking only before a near obstacle. This
    beats a single pursuer (the evader is faster) but can be cornered by several.
    """

    def __init__(
        self,
        boxes: Tensor,
        arena: Tensor,
        max_speed: float,
        max_accel: float,
        margin: float,
        num_rays: int = 16,
        lookahead: float = 15.0,
        open_space: float = 0.3,
        escape: float = 1.0,
        threat_radius: float = 15.0,
        wall_influence: float = 5.0,
        wall_repulsion: float = 1.0,
        use_kernels: bool = False,
    ) -> None:
        angles = torch.arange(num_rays, dtype=torch.float32, device=boxes.device)
        angles = angles * (2 * math.pi / num_rays)
        self.directions = torch.stack([torch.cos(angles), torch.sin(angles)], -1)  # (M, 2)
        self.boxes, self.arena = boxes, arena
        self.max_speed, self.max_accel = max_speed, max_accel
        self.margin, self.lookahead = margin, lookahead
        self.open_space, self.escape, self.threat_radius = open_space, escape, threat_radius
        self.wall_influence, self.wall_repulsion = wall_influence, wall_repulsion
        self.use_kernels = use_kernels  # act in pes.sim.kernels (its environment steps there)
        self.kernel_constants: dict | None = None  # pes.sim.kernels' copies, built on first use

    def __call__(self, v: Vehicles, counters, flags) -> tuple[Tensor, Tensor]:
        alive = flags.alive  # (E, N)
        if self.use_kernels and kernels.applies(v.x):  # the same numbers, compiled
            return kernels.flee(self, torch.stack(tuple(v)), alive)
        ex, ey, evx, evy = v.x[:, -1], v.y[:, -1], v.vx[:, -1], v.vy[:, -1]  # (E,)
        px, py = v.x[:, :-1], v.y[:, :-1]  # (E, N)
        dx, dy = ex[:, None] - px, ey[:, None] - py  # pursuer -> evader
        dist2 = (dx * dx + dy * dy).clamp(min=1.0)
        # Unit vectors weighted by (threat_radius / d)^2: a far pursuer barely counts.
        weight = torch.where(alive, self.threat_radius**2 / (dist2 * torch.sqrt(dist2)), 0.0)
        away_x, away_y = (weight * dx).sum(-1), (weight * dy).sum(-1)
        norm = torch.sqrt(away_x * away_x + away_y * away_y)
        cap = torch.clamp(1.5 / norm.clamp(min=1e-9), max=1.0)
        away_x, away_y = away_x * cap, away_y * cap
        # Repelled by the nearest obstacle: keep to the middle of the street.
        d = v.obstacle_dist[:, -1].clamp(min=1e-3)
        push = ((self.wall_influence - d) / self.wall_influence).clamp(min=0.0) ** 2 / d
        away_x = away_x - self.wall_repulsion * push * v.obstacle_dx[:, -1]
        away_y = away_y - self.wall_repulsion * push * v.obstacle_dy[:, -1]

        free = ray_distance(
            ex, ey, self.directions, self.boxes, self.arena, self.margin, self.lookahead
        )  # (E, M)
        ux, uy = self.directions[:, 0], self.directions[:, 1]  # (M,)
        # Where each heading leads, against where the pursuers will be by then: (E, M, N).
        t = (free / self.max_speed).unsqueeze(-1)  # (E, M, 1)
        gx = (ex[:, None] + ux * free).unsqueeze(-1) - (px[:, None] + v.vx[:, None, :-1] * t)
        gy = (ey[:, None] + uy * free).unsqueeze(-1) - (py[:, None] + v.vy[:, None, :-1] * t)
        gap = torch.where(alive[:, None, :], gx * gx + gy * gy, 1e6).amin(-1).clamp(max=1e6)
        score = ux * away_x[:, None] + uy * away_y[:, None]
        score = score + self.open_space * free / self.lookahead
        score = score + self.escape * torch.sqrt(gap).clamp(max=40.0) / 40.0
        score = score - 2.0 * (free < 2.0).float()
        best = score.argmax(dim=-1)  # (E,)
        best_free = free.gather(-1, best.unsqueeze(-1)).squeeze(-1)
        target_speed = self.max_speed * (best_free / 3.0).clamp(max=1.0)
        ax = (ux[best] * target_speed - evx) / (0.3 * self.max_accel)
        ay = (uy[best] * target_speed - evy) / (0.3 * self.max_accel)
        norm = torch.sqrt(ax * ax + ay * ay).clamp(min=1.0)
        return ax / norm, ay / norm


class RandomEvader:
    """Uniformly random actions in [-1, 1]^2, drawn from the environment's counter RNG."""

    def __call__(self, v: Vehicles, counters, flags) -> tuple[Tensor, Tensor]:
        key = rng.derive(counters.episode_key, counters.step)
        u = rng.uniform(key, 0 * 8 + STREAM_EVADER_RANDOM)
        w = rng.uniform(key, 1 * 8 + STREAM_EVADER_RANDOM)
        return u * 2.0 - 1.0, w * 2.0 - 1.0


EvaderModelLoader = Callable[[str, torch.device], torch.nn.Module]
"""``loader(evader_model, device)`` -> the frozen evader network ``(E, A, 8) -> (E, 2)``."""

_model_loader: EvaderModelLoader | None = None


def register_model_loader(loader: EvaderModelLoader) -> None:
    """Set how ``evader_policy="ddpg"`` loads ``EnvConfig.evader_model`` (a shipped model's name
    or a policy file). The simulator knows no learner: :mod:`pes.algos` registers its loader
    when it is imported, as ``import pes`` does."""
    global _model_loader
    _model_loader = loader


def load_model(spec: str, device: torch.device) -> torch.nn.Module:
    """The frozen evader network ``spec`` through the registered loader."""
    if _model_loader is None:
        raise ConfigError(
            "evader_policy='ddpg' needs an evader model loader: import pes (or pes.algos) first"
        )
    return _model_loader(spec, device)


class NetworkEvader:
    """A frozen evader network (the DDPG evader): ``actor(evader_obs) -> (E, 2)`` on the
    evader's observation as built by ``observe`` (a function of the state views)."""

    def __init__(self, actor: torch.nn.Module, observe: Callable[..., Tensor]) -> None:
        self.actor = actor
        self.observe = observe

    def __call__(self, v: Vehicles, counters, flags) -> tuple[Tensor, Tensor]:
        action = self.actor(self.observe(v, flags))
        return action[:, 0], action[:, 1]

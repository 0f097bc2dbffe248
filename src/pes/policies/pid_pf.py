"""PID(PF): the non-learning baseline of Table IV -- a PID velocity controller on an artificial
potential field (attraction to the evader, repulsion from the nearest obstacle).

Each pursuer acts on row 0 of its own observation (its position, velocity and the vector to
the evader) and, like a classical potential-field planner, on the map it flies in. Gains are in
SI units; see docs/policies.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from pes.sim.config import EnvConfig
from pes.sim.geometry import obstacle_distances_xy
from pes.sim.layout import make_layout


@dataclass
class PIDPFConfig:
    """Gains of the potential field and of the velocity PID."""

    cruise_speed: float = 8.0
    """Speed asked for (m/s). The observation shows only the nearest obstacle, so the one ahead
    may appear late: at 7 m/s a pursuer can still stop within half of an 11.5 m street."""
    influence: float = 4.0
    """d0 (m): obstacles closer than this repel and deflect the attraction along their surface."""
    repulsion: float = 1.5
    """Weight of the repulsion ((d0 - d) / d0)^2 against the unit attraction."""
    goal_radius: float = 6.0
    """Within this distance of the evader (m) the repulsion fades, so that the pursuer can close
    in on an evader near a wall (the usual fix of potential fields whose goal lies by an
    obstacle)."""
    lead_time: float = 2.0
    """Longest look-ahead (s) of the lead pursuit: the pursuer aims at the evader's position
    extrapolated by its distance / max speed, at most this far ahead."""
    arrival_gain: float = 1.5
    """Within ``goal_radius`` of the evader the pursuer asks for the evader's velocity plus this
    many m/s per metre of distance towards it (1/s), below the cruise speed."""
    braking: float = 0.4
    """Fraction of the maximum deceleration used to stop short of an obstacle."""
    margin: float = 1.5
    """Distance (m) from an obstacle's surface to the body at which braking aims to stop."""
    kp: float = 3.0
    """Proportional gain on the velocity error (1/s)."""
    ki: float = 0.2
    """Integral gain on the velocity error (1/s^2)."""
    kd: float = 0.05
    """Derivative gain on the velocity error (dimensionless)."""


def _unit(v: Tensor) -> Tensor:
    return v / v.norm(dim=-1, keepdim=True).clamp(min=1e-6)


class PIDPotentialField:
    """The PID(PF) pursuers. ``config`` is the scenario: its map and units.

    Desired velocity: ``cruise_speed`` (less on arrival) along the potential field's
    direction -- a unit attraction towards where the evader is going (lead pursuit), deflected
    along the surface of near obstacles it points into so that a pursuer slides round a
    building instead of pressing against it, plus a repulsion ((d0 - d) / d0)^2 from every
    building and wall closer than d0, fading near the evader -- with the speed towards each
    near obstacle capped so that the pursuer can still brake before touching it. A PID on the
    velocity error gives the acceleration command, braking first.

    Like a classical potential-field planner it knows the map (the layout of ``config``);
    each pursuer otherwise uses only row 0 of its own observation: its position and velocity
    and the vector to the evader.
    """

    def __init__(
        self, config: EnvConfig | None = None, gains: PIDPFConfig | None = None, seed: int = 0
    ) -> None:
        self.env_config = config or EnvConfig()
        self.gains = gains or PIDPFConfig()
        layout = make_layout(self.env_config)
        self.boxes = torch.tensor(layout.boxes, dtype=torch.float32).reshape(-1, 4)
        self.arena = torch.tensor([layout.width, layout.height], dtype=torch.float32)
        self.integral: Tensor | None = None
        self.last_error: Tensor | None = None
        self.fresh: Tensor | None = None  # (E,) environments whose episode just started
        self.last_evader: Tensor | None = None  # (E, N, 2) evader position seen last step

    def __call__(self, obs: Tensor, info: dict[str, Tensor]) -> Tensor:
        cfg, g = self.env_config, self.gains
        if self.boxes.device != obs.device:
            self.boxes, self.arena = self.boxes.to(obs.device), self.arena.to(obs.device)
        if self.integral is not None and self.integral.device != obs.device:
            for name in self.MEMORY:  # restored from a checkpoint, which loads to the CPU
                setattr(self, name, getattr(self, name).to(obs.device))
        scale = self.arena
        own = obs[:, :, 0]  # (E, N, 8) row 0: the pursuer itself
        pos = own[..., 0:2] * scale
        vel = own[..., 2:4] * cfg.pursuer_max_speed
        to_evader = own[..., 6:8] * scale
        if self.integral is None or self.integral.shape != pos.shape:
            self.integral = torch.zeros_like(pos)
            self.fresh = torch.ones(pos.shape[0], dtype=torch.bool, device=pos.device)
            self.last_error = torch.zeros_like(pos)
            self.last_evader = pos + to_evader
        fresh = self.fresh[:, None, None]
        # Lead pursuit: aim where the evader will be, its velocity estimated from the change
        # of its position between steps (the observation gives positions only).
        evader_pos = pos + to_evader
        evader_vel = torch.where(fresh, 0.0, (evader_pos - self.last_evader) / cfg.dt)
        self.last_evader = evader_pos
        goal = to_evader.norm(dim=-1, keepdim=True)
        lead = (goal / cfg.pursuer_max_speed).clamp(max=g.lead_time)
        attract = _unit(to_evader + evader_vel * lead)

        # Every obstacle (buildings, then walls): distance d and outward normal, (E, N, K).
        d, nx, ny = obstacle_distances_xy(pos[..., 0], pos[..., 1], self.boxes, self.arena)
        n = -torch.stack([nx, ny], dim=-1)  # (E, N, K, 2) towards each obstacle
        d = d.unsqueeze(-1)
        fade = (goal / g.goal_radius).clamp(max=1.0).unsqueeze(-2)  # (E, N, 1, 1)
        near = ((g.influence - d) / g.influence).clamp(0.0, 1.0) * fade
        into = (attract.unsqueeze(-2) * n).sum(-1, keepdim=True).clamp(min=0.0)
        attract = attract - (into * n * near.sqrt()).sum(-2)
        direction = _unit(attract - g.repulsion * (near**2 * n).sum(-2))
        # Full cruise speed far from the evader; on arrival, the evader's velocity plus a pull
        # towards it, so as to stay on it.
        cruise = min(g.cruise_speed, cfg.pursuer_max_speed)
        far = direction * cruise
        close = evader_vel + direction * g.arrival_gain * goal
        close = close * (cruise / close.norm(dim=-1, keepdim=True).clamp(min=1e-6)).clamp(max=1.0)
        desired = torch.where(goal > g.goal_radius, far, close)
        # Cap the speed towards each obstacle at what can still be braked away; the margin
        # shrinks near the evader so that a pursuer can reach an evader by a wall.
        margin = g.margin * fade.clamp(min=0.5)
        gap = (d - cfg.body_radius - margin).clamp(min=0.0)
        allowed = torch.sqrt(2 * g.braking * cfg.pursuer_max_accel * gap)
        towards = (desired.unsqueeze(-2) * n).sum(-1, keepdim=True)
        desired = desired - ((towards - allowed).clamp(min=0.0) * n).sum(-2)

        error = desired - vel
        last = torch.where(fresh, error, self.last_error)  # no derivative kick at a start
        self.fresh = torch.zeros_like(self.fresh)
        self.integral = self.integral + error * cfg.dt
        derivative = (error - last) / cfg.dt
        self.last_error = error
        accel = (g.kp * error + g.ki * self.integral + g.kd * derivative) / cfg.pursuer_max_accel
        # Braking away from the nearest obstacle comes first; what is left of the acceleration
        # budget (norm 1) goes to the rest of the command.
        nearest = n.gather(-2, d.argmin(-2, keepdim=True).expand(*d.shape[:-2], 1, 2)).squeeze(-2)
        brake = (accel * nearest).sum(-1, keepdim=True).clamp(-1.0, 0.0)
        rest = accel - brake * nearest
        room = torch.sqrt((1.0 - brake**2).clamp(min=0.0))
        rest = rest * torch.clamp(room / rest.norm(dim=-1, keepdim=True).clamp(min=1e-6), max=1.0)
        return brake * nearest + rest

    MEMORY = ("integral", "last_error", "fresh", "last_evader")
    """What the controller remembers between steps, each (E, ...) or None before the first."""

    def state_dict(self) -> dict[str, Tensor | None]:
        """What it remembers between steps (a checkpoint of a run it demonstrates in)."""
        return {name: getattr(self, name) for name in self.MEMORY}

    def load_state_dict(self, state: dict[str, Tensor | None]) -> None:
        for name in self.MEMORY:
            setattr(self, name, state[name])

    def reset(self, mask: Tensor | None = None) -> None:
        if self.integral is None:
            return
        if mask is None:
            self.integral = None
            return
        self.integral = self.integral * (~mask).to(self.integral.dtype)[:, None, None]
        self.fresh = self.fresh | mask

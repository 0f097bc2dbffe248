"""The step's rewards: every term, the paper's (eqs. 8-9) and the ones a training protocol may
add, written once for both step paths.

Each term is an elementwise formula of what the physics of a step left and of the reward's
weights (:class:`RewardWeights`), written with arithmetic and three helpers (:func:`sqrt`,
:func:`relu`, :func:`softplus`) only, so that the same function runs on tensors (the torch
step, :func:`rewards`, any batch shape and device) and on the float32 numbers of one
environment inside the compiled kernel (:func:`pes.sim._numba_step.collide` calls
:func:`pursuer_reward` and :func:`evader_reward` per environment; Numba compiles them with
its own versions of the helpers). What the terms read per pursuer (the distances, the
alive pursuers' sums and the nearest one) each path gathers in its own loop or tensor code:
:class:`StepFacts` in the torch step.

A new term is a function here, called from :func:`pursuer_reward` (or :func:`evader_reward`),
a key of :class:`pes.EnvConfig` and a field of :class:`RewardWeights` set in
:func:`reward_weights`; a term that needs a new quantity gathered across the pursuers (a sum,
the nearest one) needs it in both gatherings as well, :func:`rewards` and the kernel's loop.
``tests/test_kernels.py`` holds the two paths to the same rewards (a change of this file
compiles the kernels anew: :func:`pes.sim.kernels.ready_marker` keys on it).

Shapes: E environments, N pursuers; distances in metres, speeds in m/s. A pursuer earns its
reward for a step if it was alive when the step began.
"""

from __future__ import annotations

from typing import NamedTuple, TypeVar, Union

import numpy as np
import torch
from torch import Tensor
from torch.nn import functional

from pes.sim.config import EnvConfig

Value = TypeVar("Value", bound=Union[Tensor, float, np.float32])
"""What a term computes on: a tensor (the torch step, any shape) or one float32 number (the
kernel)."""


class RewardWeights(NamedTuple):
    """The reward's constants: Python floats for the torch step (:func:`reward_weights`; torch
    rounds each to a tensor's dtype as it operates), NumPy float32 for the kernel
    (:meth:`as_float32`, rounded as torch rounds them for float32 tensors)."""

    rho: float
    """1 / the arena's diagonal (1/m)."""
    cooperation: float
    """-cooperation_weight * rho, eq. (8)."""
    self_rho: float
    """self_weight * rho, eq. (9)."""
    safe: float
    """d_safe of eq. (9) (m)."""
    softplus_k: float
    """k of eq. (9)'s softplus (m)."""
    lead: float
    """``intercept_lead`` (s)."""
    lead_on: bool
    """Whether ``intercept_lead`` is on."""
    approach: float
    """``approach_weight``."""
    two_decel: float
    """2 * ``approach_decel`` (m/s^2)."""
    radius: float
    """The body radius (m): the approach term's gap is measured from it."""
    encirclement: float
    """``encirclement_weight``."""
    crash: float
    """``crash_reward``."""
    capture: float
    """``capture_reward``."""
    evader_crash: float
    """``evader_crash_reward``."""
    evader_capture: float
    """``evader_capture_reward``."""

    def as_float32(self) -> RewardWeights:
        """The same weights as NumPy float32 numbers, for the kernel's float32 arithmetic."""
        return RewardWeights(
            *(v if isinstance(v, bool) else np.float32(v) for v in self)  # type: ignore[arg-type]
        )


def reward_weights(cfg: EnvConfig) -> RewardWeights:
    """The :class:`RewardWeights` of ``cfg``, as Python floats."""
    rho = 1.0 / cfg.arena_diagonal
    return RewardWeights(
        rho=rho,
        cooperation=-cfg.cooperation_weight * rho,
        self_rho=cfg.self_weight * rho,
        safe=cfg.safe_distance,
        softplus_k=cfg.softplus_k,
        lead=cfg.intercept_lead,
        lead_on=bool(cfg.intercept_lead),
        approach=cfg.approach_weight,
        two_decel=2.0 * cfg.approach_decel,
        radius=cfg.body_radius,
        encirclement=cfg.encirclement_weight,
        crash=cfg.crash_reward,
        capture=cfg.capture_reward,
        evader_crash=cfg.evader_crash_reward,
        evader_capture=cfg.evader_capture_reward,
    )


# The helpers the terms may call: torch's here, Numba's in pes.sim._numba_step.
def sqrt(x: Tensor) -> Tensor:
    """The square root, elementwise."""
    return torch.sqrt(x)


def relu(x: Tensor) -> Tensor:
    """max(x, 0), elementwise."""
    return x.clamp(min=0.0)


def softplus(x: Tensor) -> Tensor:
    """log(1 + exp(x)), elementwise, linear above 20 (torch's threshold)."""
    return functional.softplus(x)


# The terms: elementwise formulas, the same on tensors and on one environment's numbers.
def softplus_obstacle_term(distance: Value, safe_distance: float, k: float) -> Value:
    """k * log(exp(0) + exp((d_safe - d_obs) / k)) of eq. (9), computed without overflow for
    any distance (also negative, inside a wall); ``distance`` and the result in metres."""
    return softplus((safe_distance - distance) / k) * k


def lead_distance(
    dx: Value, dy: Value, evader_vx: Value, evader_vy: Value, w: RewardWeights
) -> Value:
    """Not in the paper (``intercept_lead``): a pursuer's distance (m) to the evader's lead
    point, ``w.lead`` seconds ahead at its current velocity; ``dx, dy`` the pursuer's position
    minus the evader's (m), ``evader_vx, evader_vy`` the evader's velocity (m/s)."""
    lead_x = dx - evader_vx * w.lead
    lead_y = dy - evader_vy * w.lead
    return sqrt(lead_x * lead_x + lead_y * lead_y)


def pursuer_reward(
    w: RewardWeights,
    paid_sum: Value,
    charged: Value,
    obstacle: Value,
    inward: Value,
    unit_x: Value | None,
    unit_y: Value | None,
    count: Value | None,
    crashed: Value,
    success: Value,
    alive0: Value,
) -> Value:
    """One pursuer's reward for a step.

    Eq. (8), the cooperation term: ``w.cooperation`` times ``paid_sum``, the alive pursuers'
    summed distance to the evader (m). Eq. (9): minus ``w.self_rho`` times ``charged``, the
    pursuer's own distance (m), minus the softplus term of its nearest obstacle at
    ``obstacle`` m. Not in the paper: the approach term (``w.approach``: the speed at which it
    closed on that obstacle, minus ``inward`` <= 0 m/s, above the speed it could still brake
    from in its gap) and the encirclement term (``w.encirclement``: the length of the mean of
    the unit vectors from the evader to the alive pursuers, summed ``unit_x``, ``unit_y`` over
    their ``count``; unused, and may be None, where ``w.encirclement`` is 0). Then the crash
    and capture rewards; ``crashed``, ``success`` and ``alive0`` (alive when the step began:
    else the reward is 0) are 1 or 0.
    """
    own = -(w.self_rho * charged + softplus_obstacle_term(obstacle, w.safe, w.softplus_k))
    if w.approach != 0:
        brakeable = sqrt(w.two_decel * relu(obstacle - w.radius))
        own = own - w.approach * relu(-inward - brakeable)
    reward = w.cooperation * paid_sum + own
    if w.encirclement != 0:
        reward = reward - w.encirclement * sqrt(unit_x * unit_x + unit_y * unit_y) / count
    reward = reward + w.crash * crashed
    reward = reward + w.capture * success
    return reward * alive0


def evader_reward(
    w: RewardWeights, nearest_gap: Value, obstacle: Value, contact: Value, success: Value
) -> Value:
    """The evader's reward for a step: the nearest alive pursuer's distance ``nearest_gap``
    (m; 0 with none alive) times ``w.rho``, minus the softplus term of its nearest obstacle
    at ``obstacle`` m, plus its crash and capture rewards (``contact``, ``success``: 1 or 0)."""
    return (
        w.rho * nearest_gap
        - softplus_obstacle_term(obstacle, w.safe, w.softplus_k)
        + w.evader_crash * contact
        + w.evader_capture * success
    )


class StepFacts(NamedTuple):
    """What one control step left, for its rewards (the torch step)."""

    alive0: Tensor
    """(E, N) bool: the pursuers alive when the step began."""
    distances: Tensor
    """(E, N) m: each pursuer's straight-line distance to the evader after the step."""
    paid: Tensor
    """(E, N) m: the distance the reward charges (``distances``, or the path round the
    buildings with ``distance_metric="geodesic"``)."""
    dx: Tensor
    """(E, N) m: each pursuer's position minus the evader's, x."""
    dy: Tensor
    """(E, N) m: the same, y."""
    evader_vx: Tensor
    """(E, 1) m/s: the evader's velocity after the step, x."""
    evader_vy: Tensor
    """(E, 1) m/s: the same, y."""
    obstacle: Tensor
    """(E, N + 1) m: every vehicle's distance to its nearest obstacle after the step (the
    evader last)."""
    inward: Tensor
    """(E, N + 1) m/s: the velocity each vehicle had into its nearest obstacle before a contact
    stopped it (<= 0)."""
    crashed: Tensor
    """(E, N) bool: the pursuers that touched an obstacle in this step."""
    success: Tensor
    """(E,) bool: the evader was captured in this step."""
    evader_contact: Tensor
    """(E,) bool: the evader touched an obstacle in this step."""


def rewards(w: RewardWeights, facts: StepFacts) -> tuple[Tensor, Tensor]:
    """The step's rewards on tensors: the pursuers' (E, N) and the evader's (E,), from the
    facts of the whole batch (:func:`pursuer_reward`, :func:`evader_reward`)."""
    n = facts.alive0.shape[-1]
    dtype = facts.distances.dtype
    alive0 = facts.alive0.to(dtype)
    gaps = torch.where(facts.alive0, facts.distances, float("inf"))
    nearest = gaps.amin(-1, keepdim=True)  # (E, 1), inf with none alive
    charged = facts.paid
    if w.lead_on:  # all but the nearest alive pursuer are charged the lead point's distance
        lead = lead_distance(facts.dx, facts.dy, facts.evader_vx, facts.evader_vy, w)
        chaser = facts.alive0 & (facts.distances == nearest)
        charged = torch.where(chaser, facts.paid, lead)
    unit_x = unit_y = count = None
    if w.encirclement != 0:
        gap = facts.distances.clamp(min=1e-6)
        unit_x = (facts.dx / gap * alive0).sum(-1, keepdim=True)
        unit_y = (facts.dy / gap * alive0).sum(-1, keepdim=True)
        count = alive0.sum(-1, keepdim=True).clamp(min=1.0)
    pursuers = pursuer_reward(
        w,
        (facts.paid * alive0).sum(-1, keepdim=True),
        charged,
        facts.obstacle[:, :n],
        facts.inward[:, :n],
        unit_x,
        unit_y,
        count,
        facts.crashed.to(dtype),
        facts.success.unsqueeze(-1).to(dtype),
        alive0,
    )
    gap = torch.where(facts.alive0.any(-1), nearest[:, 0], 0.0)
    evader = evader_reward(
        w, gap, facts.obstacle[:, -1], facts.evader_contact.to(dtype), facts.success.to(dtype)
    )
    return pursuers, evader

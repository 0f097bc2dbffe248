"""The step's rewards: every term, the paper's (eqs. 8-9) and the ones a training protocol may
add, computed from what the physics of a step left (:class:`StepFacts`).

The torch step (:func:`pes.sim.scenario.advance`) calls :func:`pursuer_rewards` and
:func:`evader_reward`; the compiled CPU kernel of the collisions
(:func:`pes.sim._numba_step.collide`) repeats these terms in the same order inside its loop
over the environments, with their constants in :class:`pes.sim.kernels.RewardWeights` (calling
back into torch from there would double the step's time at small batches: some forty small
operations). A new term is a function here, a key of :class:`pes.EnvConfig`, a field of
``RewardWeights`` and its lines in the kernel; ``tests/test_kernels.py`` holds the two paths to
the same rewards.

Shapes: E environments, N pursuers; distances in metres, speeds in m/s. A pursuer earns its
reward for a step if it was alive when the step began.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor
from torch.nn.functional import softplus

from pes.sim.config import EnvConfig


class StepFacts(NamedTuple):
    """What one control step left, for its rewards."""

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


def softplus_obstacle_term(obstacle_dist: Tensor, safe_distance: float, k: float) -> Tensor:
    """k * log(exp(0) + exp((d_safe - d_obs) / k)) of eq. (9), computed without overflow for
    any distance (also negative, inside a wall); (...) in metres."""
    return softplus((safe_distance - obstacle_dist) / k) * k


def cooperation(cfg: EnvConfig, facts: StepFacts) -> Tensor:
    """Eq. (8): minus the alive pursuers' summed distance to the evader, over the arena's
    diagonal, times ``cooperation_weight``; (E, 1), the same for every pursuer."""
    rho = 1.0 / cfg.arena_diagonal
    alive0 = facts.alive0.to(facts.paid.dtype)
    return -cfg.cooperation_weight * rho * (facts.paid * alive0).sum(-1, keepdim=True)


def own_distance(cfg: EnvConfig, facts: StepFacts) -> Tensor:
    """The distance eq. (9) charges each pursuer (E, N) m: its own to the evader or, with
    ``intercept_lead`` (not in the paper), for all but the nearest alive pursuer the distance
    to the evader's lead point, ``intercept_lead`` seconds ahead at its current velocity."""
    if not cfg.intercept_lead:
        return facts.paid
    lead_x = facts.dx - facts.evader_vx * cfg.intercept_lead
    lead_y = facts.dy - facts.evader_vy * cfg.intercept_lead
    to_lead = torch.sqrt(lead_x * lead_x + lead_y * lead_y)
    chaser = facts.alive0 & (facts.distances == nearest_gap(facts))
    return torch.where(chaser, facts.paid, to_lead)


def nearest_gap(facts: StepFacts) -> Tensor:
    """(E, 1) m: the nearest alive pursuer's distance to the evader (inf if none is alive)."""
    return torch.where(facts.alive0, facts.distances, float("inf")).amin(-1, keepdim=True)


def own_term(cfg: EnvConfig, facts: StepFacts) -> Tensor:
    """Eq. (9), (E, N): minus ``self_weight`` times the charged distance over the arena's
    diagonal, minus the softplus obstacle term of the pursuer's nearest obstacle."""
    n = cfg.num_pursuers
    rho = 1.0 / cfg.arena_diagonal
    obstacle = softplus_obstacle_term(facts.obstacle[:, :n], cfg.safe_distance, cfg.softplus_k)
    return -(cfg.self_weight * rho * own_distance(cfg, facts) + obstacle)


def approach(cfg: EnvConfig, facts: StepFacts) -> Tensor:
    """Not in the paper (``approach_weight``), (E, N): minus the speed at which each pursuer
    closed on its nearest obstacle above the speed it could still brake from in its gap."""
    n = cfg.num_pursuers
    gap = (facts.obstacle[:, :n] - cfg.body_radius).clamp(min=0.0)
    brakeable = torch.sqrt(2.0 * cfg.approach_decel * gap)
    return -cfg.approach_weight * (-facts.inward[:, :n] - brakeable).clamp(min=0.0)


def encirclement(cfg: EnvConfig, facts: StepFacts) -> Tensor:
    """Not in the paper (``encirclement_weight``), (E, 1): minus how one-sided the alive
    pursuers are seen from the evader, the length of the mean of the unit vectors towards them
    (in [0, 1])."""
    alive0 = facts.alive0.to(facts.dx.dtype)
    gap = facts.distances.clamp(min=1e-6)
    unit_x = (facts.dx / gap * alive0).sum(-1, keepdim=True)
    unit_y = (facts.dy / gap * alive0).sum(-1, keepdim=True)
    count = alive0.sum(-1, keepdim=True).clamp(min=1.0)
    return -cfg.encirclement_weight * torch.sqrt(unit_x**2 + unit_y**2) / count


def pursuer_rewards(cfg: EnvConfig, facts: StepFacts) -> Tensor:
    """Each pursuer's reward for the step (E, N): eqs. (8)-(9), the optional terms, the crash
    and capture rewards; 0 for pursuers dead when the step began."""
    dtype = facts.distances.dtype
    own = own_term(cfg, facts)
    if cfg.approach_weight:
        own = own + approach(cfg, facts)
    reward = cooperation(cfg, facts) + own
    if cfg.encirclement_weight:
        reward = reward + encirclement(cfg, facts)
    reward = (
        reward
        + cfg.crash_reward * facts.crashed.to(dtype)
        + cfg.capture_reward * facts.success.unsqueeze(-1).to(dtype)
    )
    return reward * facts.alive0.to(dtype)


def evader_reward(cfg: EnvConfig, facts: StepFacts) -> Tensor:
    """The evader's reward (E,): the nearest alive pursuer's distance over the arena's
    diagonal (0 with none alive), minus its obstacle term, plus its crash and capture
    rewards."""
    dtype = facts.distances.dtype
    gap = torch.where(facts.alive0.any(-1), nearest_gap(facts)[:, 0], 0.0)
    obstacle = softplus_obstacle_term(facts.obstacle[:, -1], cfg.safe_distance, cfg.softplus_k)
    return (
        1.0 / cfg.arena_diagonal * gap
        - obstacle
        + cfg.evader_crash_reward * facts.evader_contact.to(dtype)
        + cfg.evader_capture_reward * facts.success.to(dtype)
    )

"""Physics units: attitude loop, limits, collisions, the obstacle term, geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import pes
from pes.errors import ConfigError
from pes.sim.dynamics import Vehicles, attitude_gains, quadrotor_step
from pes.sim.geometry import build_roadmap, geodesic_distance, nearest_obstacle, ray_distance
from pes.sim.reward import softplus_obstacle_term
from tests.conftest import set_vehicles


def _vehicles(num_envs: int, num_vehicles: int, x: float = 50.0, y: float = 50.0) -> Vehicles:
    zero = torch.zeros(num_envs, num_vehicles)
    return Vehicles(zero + x, zero + y, *([zero] * 14))


def test_attitude_gains_place_the_poles():
    kp, ki, kd, b = attitude_gains(30.0, 1.0, 0.1)
    roots = np.roots([1.0, kd, kp, ki])
    assert sorted(np.round(roots.real, 6)) == pytest.approx([-30.0, -30.0, -3.0], abs=1e-3)
    assert b == pytest.approx(1 / 1.2)


def test_achieved_acceleration_tracks_a_step_command():
    """Step response of the cascaded attitude loop (docs/scenario.md documents it)."""
    env = pes.make_env({"layout": "empty"}, seed=0)
    params = env.scenario.params
    v = _vehicles(1, 6)
    zero = torch.zeros(1, 6)
    command = torch.full((1, 6), 4.0)
    accel = []
    for _ in range(60):  # 0.6 s in 10 ms sub-steps
        before = v.vx.clone()
        v = quadrotor_step(v, command, zero, zero, zero, params, 0.01, 1)
        accel.append(float((v.vx - before)[0, 0] / 0.01))
    accel = np.array(accel)
    rise = np.argmax(accel >= 0.9 * 4.0) * 0.01
    assert 0.05 <= rise <= 0.2, f"90 % rise time {rise:.2f} s"
    assert accel.max() <= 4.0 * 1.01, "no more than 1 % overshoot"
    assert accel[-10:] == pytest.approx(4.0, rel=0.01)
    assert abs(float(v.vy[0, 0])) < 1e-6 and abs(float(v.yaw[0, 0])) < 1e-6


def test_lateral_command_rolls_the_right_way():
    env = pes.make_env({"layout": "empty"}, seed=0)
    v = _vehicles(1, 6)
    zero = torch.zeros(1, 6)
    for _ in range(50):
        v = quadrotor_step(
            v, zero, torch.full((1, 6), 3.0), zero, zero, env.scenario.params, 0.01, 1
        )
    assert float(v.vy[0, 0]) > 0.5 and float(v.roll[0, 0]) < 0  # y'' = -g tan(roll)


@pytest.mark.parametrize("dynamics", ["quadrotor", "point_mass"])
def test_limits_hold_over_long_random_rollouts(dynamics):
    cfg = pes.EnvConfig(dynamics=dynamics, crash_mode="continue", max_steps=400).validate()
    env = pes.make_env(cfg, num_envs=16, seed=3)
    env.reset()
    gen = torch.Generator().manual_seed(0)
    vmax = torch.tensor([cfg.pursuer_max_speed] * 5 + [cfg.evader_max_speed])
    amax = torch.tensor([cfg.pursuer_max_accel] * 5 + [cfg.evader_max_accel])
    prev = env.velocities.clone()
    for _ in range(400):
        actions = torch.rand(16, 5, 2, generator=gen) * 4 - 2  # also out of range: clipped
        _, _, term, trunc, info = env.step(actions)
        vel = info["velocities"]
        assert (vel.norm(dim=-1) <= vmax * (1 + 1e-5)).all()
        ok = ~(term | trunc) & ~info["crashed"].any(-1) & ~info["evader_contact"]
        accel = (vel - prev).norm(dim=-1) / cfg.dt  # average over the step
        assert (accel[ok] <= amax * 1.01).all()
        prev = env.velocities.clone()
        pos = info["positions"]
        assert (pos >= 0).all() and (pos[..., 0] <= 100).all() and (pos[..., 1] <= 100).all()
        assert (info["state"].isfinite()).all()


def test_disturbance_pushes_but_limits_hold():
    cfg = pes.EnvConfig(disturbance=True, disturbance_prob=1.0, layout="empty").validate()
    env = pes.make_env(cfg, num_envs=64, seed=0)
    env.reset()
    zero = torch.zeros(64, 5, 2)
    for _ in range(10):
        _, _, _, _, info = env.step(zero)
    speed = info["velocities"][:, :5].norm(dim=-1)
    # Without any command the 5 % weight pushes move the pursuers, a little.
    assert (speed > 0.05).float().mean() > 0.9 and (speed < 1.5).all()


def _pursuer_into_wall(crash_mode: str):
    cfg = pes.EnvConfig(layout="empty", crash_mode=crash_mode, dynamics="point_mass")
    env = pes.make_env(cfg, num_envs=1, seed=0)
    env.reset()
    x = torch.tensor([[0.9, 30.0, 40.0, 60.0, 70.0, 50.0]])
    y = torch.tensor([[50.0, 20.0, 30.0, 40.0, 60.0, 50.0]])
    vx = torch.tensor([[-8.0, 0, 0, 0, 0, 0]])
    set_vehicles(env, x=x, y=y, vx=vx, vy=torch.zeros(1, 6))
    action = torch.zeros(1, 5, 2)
    action[0, 0, 0] = -1.0
    return env, action


def test_crash_continue_pushes_out_and_stops():
    env, action = _pursuer_into_wall("continue")
    _, reward, _, _, info = env.step(action)
    assert bool(info["crashed"][0, 0]) and int(info["crashes"][0]) == 1
    assert bool(info["alive"][0, 0])
    assert float(env.positions[0, 0, 0]) == pytest.approx(0.3 + 1e-3, abs=1e-4)
    assert env.velocities[0, 0].abs().max() < 1e-6
    assert float(reward[0, 0]) < -2.0  # crash -2, plus the distance and obstacle terms
    _, reward, _, _, info = env.step(torch.zeros(1, 5, 2))
    assert not bool(info["crashed"][0, 0])  # it flies on


def test_crash_disable_damages_for_good():
    env, action = _pursuer_into_wall("disable")
    obs, reward, _, _, info = env.step(action)
    assert bool(info["crashed"][0, 0]) and not bool(info["alive"][0, 0])
    assert float(reward[0, 0]) < -2.0
    mask = info["obs_mask"][0]
    assert not mask[0].any()  # its own observation is masked
    assert not mask[1:, 1].any()  # it is masked out of every other pursuer's input
    assert obs[0, 0].abs().max() == 0 and obs[0, 1:, 1].abs().max() == 0
    where = env.positions[0, 0].clone()
    obs, reward, _, _, info = env.step(torch.ones(1, 5, 2))
    assert torch.equal(env.positions[0, 0], where) and float(reward[0, 0]) == 0.0
    assert not bool(info["crashed"][0, 0])


def test_evader_stops_at_the_surface_without_damage():
    cfg = pes.EnvConfig(layout="empty", evader_policy="external", dynamics="point_mass")
    env = pes.make_env(cfg, num_envs=1, seed=0)
    env.reset()
    x = torch.tensor([[30.0, 40.0, 50.0, 60.0, 70.0, 99.2]])
    y = torch.tensor([[20.0, 20.0, 20.0, 20.0, 20.0, 50.0]])
    set_vehicles(
        env,
        x=x,
        y=y,
        vx=torch.tensor([[0, 0, 0, 0, 0, 8.0]]),
        vy=torch.tensor([[0, 0, 0, 0, 0, 3.0]]),
    )
    _, _, term, _, info = env.step(torch.zeros(1, 5, 2), evader_actions=torch.tensor([[1.0, 0.0]]))
    assert bool(info["evader_contact"][0]) and not bool(term[0])
    assert float(env.positions[0, 5, 0]) == pytest.approx(100 - 0.3 - 1e-3, abs=1e-4)
    vel = env.velocities[0, 5]
    assert float(vel[0]) == pytest.approx(0.0, abs=1e-6) and float(vel[1]) > 2.5  # it slides


def test_softplus_obstacle_term_is_stable_everywhere():
    d = torch.tensor([-50.0, -1.0, 0.0, 0.3, 1.999, 2.0, 2.001, 5.0, 1e6])
    term = softplus_obstacle_term(d, 2.0, 1e-3)
    assert term.isfinite().all()
    expected = torch.clamp(2.0 - d, min=0.0)
    assert torch.allclose(term, expected, atol=1e-3)
    assert float(term[5]) == pytest.approx(1e-3 * math.log(2.0), rel=1e-4)  # at d_safe
    assert float(term[0]) == pytest.approx(52.0)  # deep inside a wall: linear, no overflow
    grad = torch.autograd.functional.jacobian(lambda t: softplus_obstacle_term(t, 2.0, 1e-3), d)
    assert grad.isfinite().all()


def _brute_distance(points: np.ndarray, boxes: np.ndarray, size: float) -> np.ndarray:
    segments = []
    for x0, y0, x1, y1 in list(boxes) + [[0.0, 0.0, size, size]]:
        t = np.linspace(0.0, 1.0, 2001)
        segments += [
            np.stack([x0 + (x1 - x0) * t, np.full_like(t, y0)], 1),
            np.stack([x0 + (x1 - x0) * t, np.full_like(t, y1)], 1),
            np.stack([np.full_like(t, x0), y0 + (y1 - y0) * t], 1),
            np.stack([np.full_like(t, x1), y0 + (y1 - y0) * t], 1),
        ]
    edge = np.concatenate(segments)
    return np.sqrt(((points[:, None] - edge[None]) ** 2).sum(-1)).min(1)


def test_nearest_obstacle_matches_brute_force():
    boxes = torch.tensor([[10.0, 10, 30, 30], [40, 10, 60, 30], [20, 50, 25, 80]])
    arena = torch.tensor([100.0, 100.0])
    gen = torch.Generator().manual_seed(0)
    points = torch.rand(400, 2, generator=gen) * 100
    dist, point, normal = nearest_obstacle(points, boxes, arena)
    brute = _brute_distance(points.numpy(), boxes.numpy(), 100.0)
    assert np.allclose(np.abs(dist.numpy()), brute, atol=0.06)
    inside = (
        (points[:, None, 0] > boxes[:, 0])
        & (points[:, None, 0] < boxes[:, 2])
        & (points[:, None, 1] > boxes[:, 1])
        & (points[:, None, 1] < boxes[:, 3])
    ).any(1)
    assert ((dist < 0) == inside).all()
    assert torch.allclose((points - point).norm(dim=-1), dist.abs(), atol=1e-4)
    assert torch.allclose(normal.norm(dim=-1), torch.ones(400), atol=1e-5)


def test_ray_distance():
    boxes = torch.tensor([[40.0, 40, 60, 60]])
    arena = torch.tensor([100.0, 100.0])
    dirs = torch.tensor([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0]])
    d = ray_distance(torch.tensor([20.0]), torch.tensor([50.0]), dirs, boxes, arena, 1.0, 200.0)
    assert d[0].tolist() == pytest.approx([19.0, 19.0, 49.0])
    # Starting inside the margin: blocked towards the box, free away from it.
    d = ray_distance(torch.tensor([39.5]), torch.tensor([50.0]), dirs, boxes, arena, 1.0, 200.0)
    assert d[0, 0] == 0.0 and d[0, 1] == pytest.approx(38.5)


def test_capture_needs_three_alive_pursuers_held_five_steps():
    cfg = pes.EnvConfig(layout="empty", evader_policy="external", dynamics="point_mass")
    env = pes.make_env(cfg, num_envs=1, seed=0)
    env.reset()
    x = torch.tensor([[50.5, 49.5, 50.0, 20.0, 80.0, 50.0]])
    y = torch.tensor([[50.0, 50.0, 51.0, 20.0, 80.0, 50.0]])
    set_vehicles(env, x=x, y=y, vx=torch.zeros(1, 6), vy=torch.zeros(1, 6))
    still = torch.zeros(1, 5, 2)
    for k in range(5):
        _, reward, term, _, info = env.step(still, evader_actions=torch.zeros(1, 2))
        assert bool(term[0]) == (k == 4)
    assert bool(info["success"][0]) and int(info["steps"][0]) == 5
    assert float(reward[0, 0]) > 4.0  # the capture reward, +5


def test_too_few_pursuers_left_ends_in_failure():
    cfg = pes.EnvConfig(
        num_pursuers=3, damaged=0, crash_mode="disable", layout="empty", dynamics="point_mass"
    )
    env = pes.make_env(cfg, num_envs=1, seed=0)
    env.reset()
    x = torch.tensor([[1.0, 30.0, 40.0, 50.0]])
    set_vehicles(
        env,
        x=x,
        y=torch.tensor([[50.0, 20.0, 30.0, 50.0]]),
        vx=torch.tensor([[-9.0, 0, 0, 0]]),
        vy=torch.zeros(1, 4),
    )
    action = torch.zeros(1, 3, 2)
    action[0, 0, 0] = -1
    _, _, term, _, info = env.step(action)
    assert bool(term[0]) and not bool(info["success"][0])


def test_rewards_follow_equations_8_and_9():
    cfg = pes.EnvConfig(layout="empty", evader_policy="external", dynamics="point_mass")
    env = pes.make_env(cfg, num_envs=1, seed=0)
    env.reset()
    x = torch.tensor([[20.0, 30.0, 40.0, 60.0, 1.0, 50.0]])
    y = torch.tensor([[50.0, 50.0, 50.0, 50.0, 50.0, 50.0]])
    set_vehicles(env, x=x, y=y, vx=torch.zeros(1, 6), vy=torch.zeros(1, 6))
    _, reward, _, _, info = env.step(torch.zeros(1, 5, 2), evader_actions=torch.zeros(1, 2))
    rho = 1 / math.hypot(100, 100)
    d = torch.tensor([30.0, 20.0, 10.0, 10.0, 49.0])
    d_obs = torch.tensor([20.0, 30.0, 40.0, 40.0, 1.0])
    r_co = -0.1 * rho * d.sum()
    r_self = -(0.5 * rho * d + 1e-3 * torch.nn.functional.softplus((2.0 - d_obs) / 1e-3))
    assert torch.allclose(reward[0], r_co + r_self, atol=1e-4)
    assert torch.allclose(info["distances"][0], d, atol=1e-4)
    assert float(info["evader_reward"][0]) == pytest.approx(rho * 10.0, abs=1e-4)


def one_step_rewards(x, y, vx=None, **changes):
    """Pursuers' rewards and distances, (N,) each, of one step on the empty map (or
    ``changes["layout"]``) with point-mass dynamics, from positions ``x``, ``y`` and
    x-velocities ``vx`` ((1, N + 1) each, the evader last; at rest if None), every action zero;
    ``changes`` are EnvConfig keys."""
    n = x.shape[1] - 1
    changes = {"layout": "empty", **changes}
    cfg = pes.EnvConfig(num_pursuers=n, evader_policy="external", dynamics="point_mass", **changes)
    env = pes.make_env(cfg, num_envs=1, seed=0)
    env.reset()
    vx = torch.zeros_like(x) if vx is None else vx
    set_vehicles(env, x=x, y=y, vx=vx, vy=torch.zeros_like(x))
    _, reward, _, _, info = env.step(torch.zeros(1, n, 2), evader_actions=torch.zeros(1, 2))
    return reward[0], info["distances"][0]


def test_encirclement_term_rewards_surrounding_the_evader():
    """``encirclement_weight`` adds -w |mean unit vector from the evader to the pursuers|."""

    def reward_with(x, y, weight):
        return one_step_rewards(x, y, encirclement_weight=weight)[0]

    # Four pursuers 10 m from the evader at (50, 50): on all four sides, then all to its east.
    around = (
        torch.tensor([[60.0, 40.0, 50.0, 50.0, 50.0]]),
        torch.tensor([[50.0, 50, 60, 40, 50]]),
    )
    east = (torch.tensor([[60.0, 60, 60, 60, 50]]), torch.tensor([[50.0, 50, 50, 50, 50]]))
    for x, y in (around, east):  # weight 0 is the paper's reward
        assert torch.allclose(reward_with(x, y, 0.0), reward_with(*around, 0.0), atol=1e-5)
    assert torch.allclose(reward_with(*around, 2.0), reward_with(*around, 0.0), atol=1e-5)
    assert torch.allclose(reward_with(*east, 2.0), reward_with(*east, 0.0) - 2.0, atol=1e-5)


def test_intercept_lead_charges_all_but_the_nearest_pursuer_their_distance_to_the_lead_point():
    """``intercept_lead`` T: the nearest alive pursuer keeps eq. (9)'s distance to the evader,
    the others are charged their distance to the evader's position T seconds ahead."""
    # The evader at (50, 50) flies east at 10 m/s; a pursuer ahead of it, one behind, one north.
    x, y = torch.tensor([[60.0, 20, 50, 50]]), torch.tensor([[50.0, 50, 80, 50]])
    vx = torch.tensor([[0.0, 0, 0, 10]])
    paper, d = one_step_rewards(x, y, vx, intercept_lead=0.0)
    shaped, _ = one_step_rewards(x, y, vx, intercept_lead=2.0)
    rho = 1 / math.hypot(100, 100)
    # After the step the evader is at (51, 50) at 10 m/s: its lead point is (71, 50).
    to_lead = torch.tensor([d[0], 51.0, math.hypot(21.0, 30.0)])
    assert torch.allclose(d, torch.tensor([9.0, 31.0, math.hypot(1.0, 30.0)]), atol=1e-3)
    assert torch.allclose(shaped - paper, -0.5 * rho * (to_lead - d), atol=1e-5)


def test_approach_term_charges_speed_towards_a_wall_beyond_braking_not_nearness():
    """``approach_weight`` w charges w x (the speed towards the nearest obstacle - the speed
    sqrt(2 a g) from which the pursuer stops within its gap g at ``approach_decel`` a): nothing
    at rest near a wall, flying away from it, or towards a far one; the paper's reward at w = 0."""

    def first_reward(x0, vx0, weight):
        # Pursuer 0 at (x0, 50) flying at vx0 m/s; two more at rest by the evader at (50, 50).
        x, y = torch.tensor([[x0, 50.0, 50.0, 50.0]]), torch.tensor([[50.0, 60.0, 40.0, 50.0]])
        vx = torch.tensor([[vx0, 0.0, 0.0, 0.0]])
        rewards, _ = one_step_rewards(x, y, vx, approach_weight=weight, approach_decel=2.5)
        return rewards[0].item()

    # 1 m from the arena's west wall (x = 0): at rest, or flying away; 10 m from it, towards it.
    for x0, vx0 in ((1.0, 0.0), (1.0, 4.0), (10.0, -4.0)):
        assert first_reward(x0, vx0, 0.5) == pytest.approx(first_reward(x0, vx0, 0.0), abs=1e-6)
    # Towards the wall at 4 m/s from 1 m: a step of 0.1 s ends 0.6 m from it, a gap of 0.3 m
    # past the 0.3 m body radius, brakeable from sqrt(2 x 2.5 x 0.3) m/s.
    charged = first_reward(1.0, -4.0, 0.0) - first_reward(1.0, -4.0, 0.5)
    assert charged == pytest.approx(0.5 * (4.0 - math.sqrt(1.5)), abs=0.02)
    with pytest.raises(ConfigError, match="approach_weight"):
        pes.EnvConfig(approach_weight=-1.0).validate()


def test_geodesic_distance_goes_round_the_buildings():
    """The straight distance where the segment is clear; otherwise the shortest path through
    the waypoints off the building corners, here over the top of one box."""
    boxes, arena = torch.tensor([[5.0, 0.0, 15.0, 10.0]]), torch.tensor([30.0, 30.0])
    roadmap = build_roadmap(boxes, arena, margin=1.0)
    # The box's two bottom corners lie on the arena's wall: only the top ones are waypoints.
    assert torch.equal(roadmap.nodes, torch.tensor([[4.0, 11.0], [16.0, 11.0]]))
    p = torch.tensor([[[0.0, 5.0], [0.0, 20.0], [10.0, 20.0]]])
    q = torch.tensor([[20.0, 5.0]])
    over = math.hypot(4.0, 6.0) + 12.0 + math.hypot(4.0, 6.0)
    by_16_11 = math.hypot(16.0, 9.0) + math.hypot(4.0, 6.0)  # (0, 20) sees (16, 11)
    expected = torch.tensor([[over, by_16_11, math.hypot(10.0, 15.0)]])
    assert torch.allclose(geodesic_distance(p, q, boxes, roadmap), expected, atol=1e-4)


def test_geodesic_metric_charges_the_path_round_a_building():
    """``distance_metric="geodesic"``: a pursuer with a building between it and the evader is
    charged the path round it in eqs. (8)-(9); with a clear line nothing changes; capture and
    ``info["distances"]`` stay straight. The evaluation protocol restores the straight one."""
    # Default grid: the west block spans x 11.5-29.5, y 41-59; the centre block is removed.
    # Pursuer 0 west of it, pursuers 1 and 2 in the streets south and west of the centre.
    x, y = torch.tensor([[5.0, 50.0, 35.0, 50.0]]), torch.tensor([[50.0, 35.0, 50.0, 50.0]])
    paper, d = one_step_rewards(x, y, layout="grid")
    path, d_path = one_step_rewards(x, y, layout="grid", distance_metric="geodesic")
    assert torch.allclose(d, d_path) and d[0] == pytest.approx(45.0, abs=1e-3)
    # Round the block's south-west and south-east waypoints, 1 m off its corners.
    extra = math.hypot(5.5, 10.0) + 20.0 + math.hypot(19.5, 10.0) - 45.0
    rho = 1 / math.hypot(100, 100)
    charged = torch.tensor([0.1 + 0.5, 0.1, 0.1]) * rho * extra
    assert torch.allclose(paper - path, charged, atol=1e-5)
    evaluated = pes.EnvConfig(distance_metric="geodesic").for_evaluation()
    assert evaluated.distance_metric == "euclidean"
    with pytest.raises(ConfigError, match="distance_metric"):
        pes.EnvConfig(distance_metric="manhattan").validate()


def _rollout_clearance(num_envs: int, steps: int, seed: int = 0) -> tuple[float, int]:
    """Drive pursuers on random headings held 25 steps (so that they reach walls and corners)
    with the disturbance on; return the smallest distance from an alive vehicle centre to any
    wall or building over the rollout, less the body radius, and the number of contacts."""
    from pes.sim.geometry import obstacle_distances_xy

    cfg = pes.EnvConfig(disturbance=True)
    env = pes.make_env(cfg, num_envs=num_envs, seed=seed)
    env.reset(seed=seed)
    boxes = torch.as_tensor(env.layout.boxes, dtype=torch.float32)
    arena = torch.tensor([env.layout.width, env.layout.height])
    gen = torch.Generator().manual_seed(seed)
    worst, contacts = math.inf, 0
    for t in range(steps):
        if t % 25 == 0:
            heading = torch.rand(num_envs, cfg.num_pursuers, 2, generator=gen) * 2 - 1
        _, _, _, _, info = env.step(heading)
        pos = info["positions"]  # after the step, before any auto-reset
        dist = obstacle_distances_xy(pos[..., 0], pos[..., 1], boxes, arena)[0].amin(-1)
        alive = torch.cat([info["alive"], torch.ones_like(info["alive"][:, :1])], dim=1)
        worst = min(worst, float(dist[alive].min()) - cfg.body_radius)
        contacts += int(info["crashed"].sum() + info["evader_contact"].sum())
    return worst, contacts


def test_no_centre_within_the_body_radius_of_any_obstacle():
    """Collisions leave both walls of a corner and every building face at once (docs/scenario.md,
    "Collisions"): a pursuer once sat at (0.138, 0.301) in a corner, and centres ended up
    outside the arena."""
    worst, contacts = _rollout_clearance(64, 300)
    assert contacts > 100  # the rollout does reach the walls
    assert worst >= -1e-5, f"a centre {-worst:.4f} m inside the body radius"


@pytest.mark.slow
def test_no_centre_within_the_body_radius_of_any_obstacle_long():
    worst, _ = _rollout_clearance(1024, 2000, seed=1)
    assert worst >= -1e-5, f"a centre {-worst:.4f} m inside the body radius"


def test_corner_contact_resolves_both_walls():
    """A pursuer driven into the lower-left corner ends at the body radius from both walls."""
    cfg = pes.EnvConfig(layout="empty", dynamics="point_mass", max_steps=400)
    env = pes.make_env(cfg, seed=0)
    env.reset(seed=0)
    x0 = torch.tensor([[0.5, 50.0, 51.0, 52.0, 53.0, 70.0]])
    set_vehicles(env, x=x0, y=torch.tensor([[0.5, 50.0, 50.0, 50.0, 50.0, 70.0]]))
    for _ in range(30):
        _, _, _, _, info = env.step(torch.tensor([[[-1.0, -1.0]] + [[0.0, 0.0]] * 4]))
        x, y = info["positions"][0, 0].tolist()
        assert x >= cfg.body_radius and y >= cfg.body_radius, (x, y)
    assert x == pytest.approx(cfg.body_radius + 1e-3, abs=1e-5)
    assert y == pytest.approx(cfg.body_radius + 1e-3, abs=1e-5)

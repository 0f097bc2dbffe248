"""The pursuit-evasion scenario as pure batched functions of a packed state (docs/scenario.md).

The state is a dict of four tensors, packed so that a compiled step has few inputs and outputs
and every field is a contiguous (E, A) block (E environments, A = N pursuers + the evader):

=========== ================== ==============================================================
key         shape              contents
=========== ================== ==============================================================
vehicles    (16, E, A) float   the fields of :class:`~pes.sim.dynamics.Vehicles`: position,
                               velocity, attitude, attitude rates and integrals, and the
                               nearest obstacle (signed distance and vector to its point)
counters    (7, E) int64       :class:`Counters`: random key, episode, its key, step, capture
                               hold, crashes this episode, damage step
flags       (2, E, N) bool     :class:`Flags`: alive, chosen to be damaged this episode
history     (E, n, A, 4)       the last n frames of [position, velocity], normalised as the
                               observations, oldest first, zero before the episode start
=========== ================== ==============================================================

:func:`step_core` is the environment step -- evader policy, dynamics, collisions, damage,
capture, rewards and observations -- and :func:`reset_pass` the auto-reset of finished
environments; both have static shapes and no Python loop over environments, vehicles or
buildings, so that ``torch.compile`` fuses each into one graph. On the CPU, when torch is not
compiling, most of both runs in the compiled kernels of :mod:`pes.sim.kernels` instead, which
repeat this code's arithmetic (the same numbers to float32 rounding).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import torch
from torch import Tensor

from pes.errors import ConfigError
from pes.sim import kernels, rng
from pes.sim.config import EnvConfig
from pes.sim.dynamics import (
    GRAVITY,
    VehicleParams,
    Vehicles,
    attitude_gains,
    clip_norm,
    point_mass_step,
    quadrotor_step,
)
from pes.sim.evader import EvaderPolicy, FleeEvader, NetworkEvader, RandomEvader, load_model
from pes.sim.geometry import (
    Roadmap,
    build_roadmap,
    geodesic_distance,
    nearest_obstacle,
    nearest_obstacle_xy,
    obstacle_distances_xy,
    pick_nearest,
)
from pes.sim.layout import Layout, make_layout
from pes.sim.reward import RewardWeights, StepFacts, reward_weights, rewards

OBS_FEATURES = 8
"""Numbers per row of an observation (Table I)."""

# Independent random streams: the index of every draw is (what * 8 + stream), so that the
# draws of different purposes never share an index under one key.
STREAM_SPAWN = 1
STREAM_DAMAGE = 2
STREAM_DAMAGE_STEP = 3
STREAM_DISTURBANCE = 4

SPAWN_CELL = 0.5  # m, resolution of the grid of free start cells
CONTACT_GAP = 1e-3  # m, how far outside the body radius a pushed-out vehicle is put
CONTACT_PASSES = 1  # passes of resolve_contacts after the push out of the nearest obstacle (one
# leaves orthogonal pairs -- the corners of walls and blocks -- together; more only matter where
# obstacles stand closer than a body diameter, where no free spot need exist)
ROADMAP_CLEARANCE = 0.7  # m beyond the body radius: the waypoints round building corners


class Counters(NamedTuple):
    """Per-environment integers, each (E,) int64."""

    key: Tensor  # the environment's random key (see pes.sim.rng)
    episode: Tensor  # episodes started since the last seeded reset
    episode_key: Tensor  # the random key of this episode, derived from key and episode
    step: Tensor  # control steps taken in this episode
    hold: Tensor  # consecutive steps the capture condition has held
    crashes: Tensor  # pursuer crashes so far this episode
    damage_step: Tensor  # the step at which the chosen pursuers are damaged


class Flags(NamedTuple):
    """Per-pursuer booleans, each (E, N)."""

    alive: Tensor  # neither damaged nor (crash_mode=disable) crashed
    damage_mask: Tensor  # chosen to be damaged this episode (damaged=K)


def unpack(state: dict[str, Tensor]) -> tuple[Vehicles, Counters, Flags]:
    """Named views of the packed state tensors."""
    return (
        Vehicles(*state["vehicles"].unbind(0)),
        Counters(*state["counters"].unbind(0)),
        Flags(*state["flags"].unbind(0)),
    )


def pack(v: Vehicles, c: Counters, f: Flags, history: Tensor) -> dict[str, Tensor]:
    """The packed state of :func:`unpack`'s views and a history tensor."""
    return {
        "vehicles": torch.stack(tuple(v)),
        "counters": torch.stack(tuple(c)),
        "flags": torch.stack(tuple(f)),
        "history": history,
    }


@dataclass
class Scenario:
    """The constant part of a batch of environments: configuration, layout and tensors."""

    config: EnvConfig
    layout: Layout
    device: torch.device
    boxes: Tensor  # (B, 4) m
    arena: Tensor  # (2,) m
    params: VehicleParams
    pursuer_cells: Tensor  # (Mp, 2) centres of free start cells for pursuers, m
    evader_cells: Tensor  # (Me, 2) centres of free start cells for the evader, m
    other_index: Tensor  # (N, N) row k of pursuer i's observation shows pursuer other_index[i, k]
    vel_scale: float  # pursuer max speed, m/s: velocity normaliser of observations
    # (N + 1,) int64 0..N, the vehicles' numbers that index their random draws. A tensor read
    # from memory, not torch.arange in the step: Inductor folds an arange into a CUDA kernel's
    # int32 index arithmetic, where Triton refuses the hash's constants above 2**31.
    vehicle: Tensor
    reward_weights: RewardWeights  # the reward's constants (pes.sim.reward)
    evader_policy: EvaderPolicy | None = field(default=None)
    roadmap: Roadmap | None = field(default=None)  # distance_metric="geodesic" only
    kernels: bool = False  # steps with pes.sim.kernels (chosen when the environment is made)
    kernel_constants: kernels.Constants | None = field(default=None, repr=False)

    @property
    def num_pursuers(self) -> int:
        return self.config.num_pursuers


def _free_cells(layout: Layout, config: EnvConfig, region: str) -> np.ndarray:
    """Centres (M, 2) of the SPAWN_CELL squares that lie wholly inside a start region and at
    least ``spawn_clearance`` from every obstacle."""
    w, h = layout.width, layout.height
    xs = np.arange(SPAWN_CELL / 2, w, SPAWN_CELL)
    ys = np.arange(SPAWN_CELL / 2, h, SPAWN_CELL)
    grid = np.stack(np.meshgrid(xs, ys, indexing="xy"), -1).reshape(-1, 2)
    half_diag = SPAWN_CELL / math.sqrt(2)
    arena = torch.tensor([w, h], dtype=torch.float64)
    dist, _, _ = nearest_obstacle(torch.as_tensor(grid), torch.as_tensor(layout.boxes), arena)
    ok = dist.numpy() >= config.spawn_clearance + config.body_radius + half_diag
    if region == "pursuer":
        edge = np.minimum.reduce([grid[:, 0], w - grid[:, 0], grid[:, 1], h - grid[:, 1]])
        ok &= edge <= config.pursuer_spawn_band - half_diag
    else:
        centre = np.array([w / 2, h / 2])
        ok &= np.linalg.norm(grid - centre, axis=1) <= config.evader_spawn_radius - half_diag
    return grid[ok]


def build_scenario(config: EnvConfig, device: torch.device) -> Scenario:
    """Resolve the layout, the vehicle constants and the start regions of ``config``."""
    layout = make_layout(config)
    n = config.num_pursuers
    pursuer_cells = _free_cells(layout, config, "pursuer")
    evader_cells = _free_cells(layout, config, "evader")
    if len(pursuer_cells) == 0:
        raise ConfigError(
            f"the layout leaves no free room to spawn pursuers within "
            f"{config.pursuer_spawn_band:g} m of the arena edge"
        )
    if len(evader_cells) == 0:
        raise ConfigError(
            f"the layout leaves no free room to spawn the evader within "
            f"{config.evader_spawn_radius:g} m of the centre"
        )

    def per_vehicle(pursuer: float, evader: float) -> Tensor:
        return torch.tensor([pursuer] * n + [evader], dtype=torch.float32, device=device)

    kp, ki, kd, weight = attitude_gains(config.attitude_bandwidth, config.attitude_damping)
    params = VehicleParams(
        mass=per_vehicle(config.pursuer_mass, config.evader_mass),
        max_speed=per_vehicle(config.pursuer_max_speed, config.evader_max_speed),
        max_accel=per_vehicle(config.pursuer_max_accel, config.evader_max_accel),
        ixx=per_vehicle(config.pursuer_inertia[0], config.evader_inertia[0]),
        iyy=per_vehicle(config.pursuer_inertia[1], config.evader_inertia[1]),
        izz=per_vehicle(config.pursuer_inertia[2], config.evader_inertia[2]),
        kp=kp,
        ki=ki,
        kd=kd,
        setpoint_weight=weight,
        max_tilt=math.radians(config.max_tilt_deg),
    )
    others = torch.tensor(
        [[i] + [j for j in range(n) if j != i] for i in range(n)], dtype=torch.long, device=device
    )
    boxes = torch.tensor(layout.boxes, dtype=torch.float32, device=device).reshape(-1, 4)
    arena = torch.tensor([layout.width, layout.height], dtype=torch.float32, device=device)
    scenario = Scenario(
        config=config,
        layout=layout,
        device=device,
        boxes=boxes,
        arena=arena,
        params=params,
        pursuer_cells=torch.tensor(pursuer_cells, dtype=torch.float32, device=device),
        evader_cells=torch.tensor(evader_cells, dtype=torch.float32, device=device),
        other_index=others,
        vel_scale=config.pursuer_max_speed,
        vehicle=torch.arange(config.num_vehicles, device=device),
        reward_weights=reward_weights(config),
        kernels=kernels.usable(device),
    )
    if config.distance_metric == "geodesic":
        scenario.roadmap = build_roadmap(boxes, arena, config.body_radius + ROADMAP_CLEARANCE)
    if config.evader_policy == "flee":
        scenario.evader_policy = FleeEvader(
            boxes,
            arena,
            config.evader_max_speed,
            config.evader_max_accel,
            margin=config.body_radius + 0.7,
            use_kernels=scenario.kernels,
        )
    elif config.evader_policy == "random":
        scenario.evader_policy = RandomEvader()
    elif config.evader_policy == "ddpg":
        actor = load_model(config.evader_model, device)
        scenario.evader_policy = NetworkEvader(
            actor, lambda v, f: observe(scenario, v, f)["evader_obs"]
        )
    return scenario


# --- observations ----------------------------------------------------------------------------


def observe(sc: Scenario, v: Vehicles, f: Flags) -> dict[str, Tensor]:
    """Observations of every pursuer and of the evader, and the global state.

    Returns:
        obs: (E, N, N, 8) -- for pursuer i, row 0 is itself: [position, velocity, vector to its
            nearest obstacle point, vector to the evader]; row k >= 1 is pursuer
            ``other_index[i, k]``: [position and velocity relative to i, vector from it to its
            nearest obstacle point, vector from it to the evader] (Table I). Positions and
            vectors are divided by the arena size, velocities by the pursuer max speed. Rows of
            dead pursuers, and every row of a dead pursuer's own observation, are zero.
        obs_mask: (E, N, N) bool, which rows are real.
        state: (E, A, 8) the global state: row j < N is pursuer j's row-0 features (zero if
            dead), row N the evader: [position, velocity, vector to its nearest obstacle, 0, 0].
        evader_obs: (E, A, 8) the evader's view: row 0 itself [position, velocity, vector to
            its nearest obstacle, vector to the nearest alive pursuer]; row 1 + j pursuer j:
            [position and velocity relative to the evader, vector from it to its nearest
            obstacle, 0, 0] (zero if dead). Velocities divided by the evader's max speed.
    """
    if sc.kernels and kernels.applies(v.x):  # the same numbers, compiled (pes.sim.kernels)
        return kernels.observe(sc, torch.stack(tuple(v)), f.alive)
    n = sc.num_pursuers
    alive = f.alive
    width, height = sc.arena[0], sc.arena[1]
    vscale = sc.vel_scale
    px, py = v.x / width, v.y / height  # (E, A)
    qx, qy = v.obstacle_dx / width, v.obstacle_dy / height
    to_ex, to_ey = px[:, n:] - px[:, :n], py[:, n:] - py[:, :n]  # (E, N)
    rows = torch.stack(
        [
            px[:, :n],
            py[:, :n],
            v.vx[:, :n] / vscale,
            v.vy[:, :n] / vscale,
            qx[:, :n],
            qy[:, :n],
            to_ex,
            to_ey,
        ],
        dim=-1,
    )  # (E, N, 8)
    picked = rows[:, sc.other_index]  # (E, N, N, 8)
    # Rows k >= 1 hold position and velocity relative to pursuer i.
    is_self = torch.arange(n, device=rows.device) == 0
    relative = torch.cat([rows[..., :4], torch.zeros_like(rows[..., 4:])], dim=-1)
    obs = picked - torch.where(is_self[:, None], 0.0, relative[:, :, None, :])
    mask = alive[:, sc.other_index] & alive[:, :, None]
    obs = obs * mask.unsqueeze(-1)

    alive_f = alive.unsqueeze(-1).to(rows.dtype)
    zero = torch.zeros_like(px[:, -1])
    evader_row = torch.stack(
        [
            px[:, -1],
            py[:, -1],
            v.vx[:, -1] / vscale,
            v.vy[:, -1] / vscale,
            qx[:, -1],
            qy[:, -1],
            zero,
            zero,
        ],
        dim=-1,
    )
    global_state = torch.cat([rows * alive_f, evader_row[:, None]], dim=1)

    e_vscale = sc.config.evader_max_speed
    gap = (to_ex * to_ex + to_ey * to_ey).masked_fill(~alive, float("inf"))
    nearest = gap.argmin(dim=-1, keepdim=True)  # (E, 1)
    e_self = torch.stack(
        [
            px[:, -1],
            py[:, -1],
            v.vx[:, -1] / e_vscale,
            v.vy[:, -1] / e_vscale,
            qx[:, -1],
            qy[:, -1],
            -to_ex.gather(1, nearest)[:, 0],
            -to_ey.gather(1, nearest)[:, 0],
        ],
        dim=-1,
    )
    zeros = torch.zeros_like(px[:, :n])
    e_rows = (
        torch.stack(
            [
                -to_ex,
                -to_ey,
                (v.vx[:, :n] - v.vx[:, n:]) / e_vscale,
                (v.vy[:, :n] - v.vy[:, n:]) / e_vscale,
                qx[:, :n],
                qy[:, :n],
                zeros,
                zeros,
            ],
            dim=-1,
        )
        * alive_f
    )
    evader_obs = torch.cat([e_self[:, None], e_rows], dim=1)
    return {"obs": obs, "obs_mask": mask, "state": global_state, "evader_obs": evader_obs}


VIEW_KEYS = ("obs", "obs_mask", "state", "evader_obs")


def history_frame(sc: Scenario, v: Vehicles, alive: Tensor) -> Tensor:
    """One history frame (E, A, 4): [position / arena size, velocity / pursuer max speed] of
    every vehicle, pursuers first, dead pursuers zeroed."""
    frame = torch.stack(
        [v.x / sc.arena[0], v.y / sc.arena[1], v.vx / sc.vel_scale, v.vy / sc.vel_scale], -1
    )
    keep = torch.cat([alive, torch.ones_like(alive[:, :1])], dim=1)
    return frame * keep.unsqueeze(-1)


# --- reset -----------------------------------------------------------------------------------


def spawn(sc: Scenario, key: Tensor, episode: Tensor) -> dict[str, Tensor]:
    """Initial states (docs/scenario.md, "Start") of the episodes ``episode`` (E,) of environments
    ``key`` (E,): pursuers at free spots near the edge, the evader near the centre, at rest."""
    cfg = sc.config
    n = cfg.num_pursuers
    device = key.device
    vehicle = sc.vehicle

    episode_key = rng.derive(key, episode)

    def draw(part: int) -> Tensor:  # (E, A) uniforms
        return rng.uniform(episode_key[:, None], (vehicle * 3 + part) * 8 + STREAM_SPAWN)

    # Uniform over free cells, then uniform inside the cell.
    is_pursuer = vehicle < n
    count = torch.where(is_pursuer, sc.pursuer_cells.shape[0], sc.evader_cells.shape[0])
    cell = (draw(0) * count).long().clamp(max=count - 1)
    cells = torch.where(
        is_pursuer[:, None],
        sc.pursuer_cells[cell.clamp(max=sc.pursuer_cells.shape[0] - 1)],
        sc.evader_cells[cell.clamp(max=sc.evader_cells.shape[0] - 1)],
    )  # (E, A, 2)
    x = cells[..., 0] + (draw(1) - 0.5) * SPAWN_CELL
    y = cells[..., 1] + (draw(2) - 0.5) * SPAWN_CELL
    dist, nx, ny = nearest_obstacle_xy(x, y, sc.boxes, sc.arena)
    zero = torch.zeros_like(x)
    v = Vehicles(x, y, *([zero] * 11), dist, -nx * dist, -ny * dist)

    if cfg.damaged > 0:
        rank = rng.uniform(episode_key[:, None], vehicle[:n] * 8 + STREAM_DAMAGE)
        damage_mask = rank.argsort(dim=1).argsort(dim=1) < cfg.damaged
    else:
        damage_mask = torch.zeros(key.shape[0], n, dtype=torch.bool, device=device)
    if cfg.damage_step == "random":
        draw_step = rng.uniform(episode_key, STREAM_DAMAGE_STEP)
        damage_step = (draw_step * (cfg.max_steps // 2 + 1)).long()
    else:
        damage_step = torch.full_like(key, int(cfg.damage_step))
    alive = ~(damage_mask & (damage_step <= 0)[:, None])
    zeros = torch.zeros_like(key)
    counters = Counters(key, episode, episode_key, zeros, zeros, zeros, damage_step)

    frame = history_frame(sc, v, alive)
    history = torch.cat(
        [frame.new_zeros(key.shape[0], cfg.history_length - 1, n + 1, 4), frame[:, None]], 1
    )
    return pack(v, counters, Flags(alive, damage_mask), history)


# --- step --------------------------------------------------------------------------------------


def _disturbance(sc: Scenario, c: Counters) -> tuple[Tensor, Tensor]:
    """Horizontal disturbance forces (E, A) x and y in newtons for this step (§V-B4)."""
    cfg = sc.config
    vehicle = sc.vehicle
    key = rng.derive(c.episode_key, c.step)[:, None]  # (E, 1)
    on = rng.uniform(key, (vehicle * 2) * 8 + STREAM_DISTURBANCE) < cfg.disturbance_prob
    angle = rng.uniform(key, (vehicle * 2 + 1) * 8 + STREAM_DISTURBANCE) * (2 * math.pi)
    magnitude = torch.where(on, cfg.disturbance_scale * GRAVITY * sc.params.mass, 0.0)
    return torch.cos(angle) * magnitude, torch.sin(angle) * magnitude


def resolve_contacts(
    x: Tensor,
    y: Tensor,
    vx: Tensor,
    vy: Tensor,
    dists: Tensor,
    nxs: Tensor,
    nys: Tensor,
    radius: float,
) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor, Tensor]:
    """Push vehicles (E, A) -- pursuers, then the evader last -- out of every wall and
    building still within ``radius`` of their centre, all obstacles at once, in
    :data:`CONTACT_PASSES` passes.

    ``dists`` (E, A, K) are the signed distances of the K obstacles from (x, y) and ``nxs``,
    ``nys`` their outward normals (:func:`obstacle_distances_xy`, possibly measured before a
    move and carried along it to first order). Each obstacle closer than ``radius`` pushes the
    centre along its normal to ``radius + CONTACT_GAP``; the pushes are combined per axis (the
    largest each way), so that the two walls of a corner are left together and two touching
    buildings do not push twice. Distances are carried along each push to first order: exact
    for walls and building faces and, the distance to a convex box being convex, never more
    than the true distance near a building's corner, so a push is never too short. A pursuer so
    pushed stops; the evader loses its velocity into each obstacle. Vehicles clear of every
    obstacle are not changed at all. Returns x, y, vx, vy, the distances (E, A, K) and
    ``touched`` (E, A) bool: pushed in some pass."""
    touched = torch.zeros_like(x, dtype=torch.bool)
    for _ in range(CONTACT_PASSES):  # a fixed count: no loop over vehicles or obstacles
        over = dists < radius
        hit = over.any(-1)
        push = torch.where(over, radius + CONTACT_GAP - dists, 0.0)
        dx, dy = _per_axis(nxs * push), _per_axis(nys * push)
        x, y = x + dx, y + dy
        dists = dists + nxs * dx.unsqueeze(-1) + nys * dy.unsqueeze(-1)
        # The evader (last) slides: it loses its velocity into each obstacle it touches.
        enx, eny = nxs[:, -1], nys[:, -1]  # (E, K)
        inward = (vx[:, -1:] * enx + vy[:, -1:] * eny).clamp(max=0.0)
        inward = torch.where(over[:, -1], inward, 0.0)
        slide_x = vx[:, -1] - _per_axis(inward * enx)
        slide_y = vy[:, -1] - _per_axis(inward * eny)
        # Pursuers stop.
        vx = torch.where(hit, torch.cat([torch.zeros_like(vx[:, :-1]), slide_x[:, None]], 1), vx)
        vy = torch.where(hit, torch.cat([torch.zeros_like(vy[:, :-1]), slide_y[:, None]], 1), vy)
        touched = touched | hit
    return x, y, vx, vy, dists, touched


def _per_axis(moves: Tensor) -> Tensor:
    """Combine (..., K) moves along one axis: the largest one each way, (...)."""
    return moves.amax(-1).clamp(min=0.0) + moves.amin(-1).clamp(max=0.0)


def advance(
    sc: Scenario, state: dict[str, Tensor], actions: Tensor, evader_action: Tensor | None
) -> tuple[dict[str, Tensor], dict[str, Tensor]]:
    """One control step of every environment, without auto-reset.

    Args:
        actions: (E, N, 2) pursuer actions in [-1, 1] (desired acceleration / max accel).
        evader_action: (E, 2) evader action, or None to run the configured evader policy.

    Returns:
        the stepped state and a dict of per-step outputs: ``reward`` (E, N), ``evader_reward``
        (E,), ``terminated``, ``truncated``, ``success`` (E,) bool, ``crashed`` (E, N) bool,
        ``evader_contact`` (E,) bool, ``distances`` (E, N) m, and the stepped ``steps``,
        ``crashes`` (E,), ``alive`` (E, N), ``positions`` and ``velocities`` (E, A, 2).
    """
    cfg, p = sc.config, sc.params
    n = cfg.num_pursuers
    v, c, f = unpack(state)
    alive0 = f.alive
    if evader_action is None:
        assert sc.evader_policy is not None
        eax, eay = sc.evader_policy(v, c, f)
    else:
        eax, eay = evader_action[:, 0], evader_action[:, 1]
    fast = sc.roadmap is None and sc.kernels and kernels.applies(v.x)  # pes.sim.kernels
    if fast and cfg.dynamics == "quadrotor":
        force = _disturbance(sc, c) if cfg.disturbance else None
        moved = kernels.move_quadrotors(sc, state["vehicles"], actions, eax, eay, alive0, force)
        return kernels.collide(sc, state, moved)
    ax = torch.cat([actions[..., 0] * alive0, eax[:, None]], dim=1)  # (E, A); dead ones idle
    ay = torch.cat([actions[..., 1] * alive0, eay[:, None]], dim=1)
    ax, ay = clip_norm(ax * p.max_accel, ay * p.max_accel, p.max_accel)
    active = torch.cat([alive0, torch.ones_like(alive0[:, :1])], dim=1)  # (E, A)
    if cfg.disturbance:
        fx, fy = _disturbance(sc, c)
        fx, fy = fx * active, fy * active
    else:
        fx = fy = torch.zeros_like(ax)

    if cfg.dynamics == "quadrotor":
        moved = quadrotor_step(v, ax, ay, fx, fy, p, cfg.dt, cfg.physics_substeps, sc.kernels)
    else:
        moved = point_mass_step(v, ax, ay, fx, fy, p, cfg.dt, cfg.physics_substeps)
    if fast:  # the rest, compiled
        return kernels.collide(sc, state, torch.stack(moved[:13]))
    # Dead pursuers stay where they fell, at rest.
    moved = Vehicles(
        *(
            torch.where(active, new, old if i < 2 else 0.0)
            for i, (new, old) in enumerate(zip(moved, v))
        )
    )

    # Collisions with buildings and walls: push out of the nearest obstacle along its normal.
    dists, nxs, nys = obstacle_distances_xy(moved.x, moved.y, sc.boxes, sc.arena)  # (E, A, K)
    dist, nx, ny = pick_nearest(dists, nxs, nys, sc.boxes.shape[0])
    contact = dist < cfg.body_radius
    push = torch.where(contact, cfg.body_radius + CONTACT_GAP - dist, 0.0)
    x, y = moved.x + nx * push, moved.y + ny * push
    dist = dist + push
    crashed = contact[:, :n] & alive0
    # Pursuers that crash stop; the evader loses only the velocity into the obstacle.
    inward = (moved.vx * nx + moved.vy * ny).clamp(max=0.0)
    is_pursuer = torch.arange(n + 1, device=x.device) < n
    stop = contact & is_pursuer
    slide = contact & ~is_pursuer
    vx = torch.where(stop, 0.0, torch.where(slide, moved.vx - inward * nx, moved.vx))
    vy = torch.where(stop, 0.0, torch.where(slide, moved.vy - inward * ny, moved.vy))
    # That push leaves the nearest obstacle only: in a corner (two walls, a wall and a building,
    # two buildings) the others may still hold the body. Leave them all.
    dists = dists + nxs * (nx * push).unsqueeze(-1) + nys * (ny * push).unsqueeze(-1)
    x, y, vx, vy, dists, touched = resolve_contacts(x, y, vx, vy, dists, nxs, nys, cfg.body_radius)
    contact = contact | touched
    crashed = contact[:, :n] & alive0
    again, anx, any_ = pick_nearest(dists, nxs, nys, sc.boxes.shape[0])
    dist = torch.where(touched, again, dist)
    nx, ny = torch.where(touched, anx, nx), torch.where(touched, any_, ny)
    moved = moved._replace(
        x=x, y=y, vx=vx, vy=vy, obstacle_dist=dist, obstacle_dx=-nx * dist, obstacle_dy=-ny * dist
    )
    alive = alive0 & ~crashed if cfg.crash_mode == "disable" else alive0

    step = c.step + 1
    alive = alive & ~(f.damage_mask & (step >= c.damage_step)[:, None])

    # Capture (§II-B "Done").
    dx, dy = x[:, :n] - x[:, n:], y[:, :n] - y[:, n:]
    distances = torch.sqrt(dx * dx + dy * dy)  # (E, N)
    near = ((distances < cfg.capture_radius) & alive).sum(-1)
    hold = torch.where(near >= cfg.capture_count, c.hold + 1, 0)
    success = hold >= cfg.capture_hold
    terminated = success | (alive.sum(-1) < cfg.capture_count)
    truncated = (step >= cfg.max_steps) & ~terminated

    paid = distances  # the distance the reward charges
    if sc.roadmap is not None:  # Not in the paper: the path round the buildings
        pursuers = torch.stack([x[:, :n], y[:, :n]], dim=-1)
        evader = torch.stack([x[:, n], y[:, n]], dim=-1)
        paid = geodesic_distance(pursuers, evader, sc.boxes, sc.roadmap)
    facts = StepFacts(
        alive0=alive0,
        distances=distances,
        paid=paid,
        dx=dx,
        dy=dy,
        evader_vx=vx[:, n:],
        evader_vy=vy[:, n:],
        obstacle=dist,
        inward=inward,
        crashed=crashed,
        success=success,
        evader_contact=contact[:, -1],
    )

    reward, evader_reward = rewards(sc.reward_weights, facts)
    crashes = c.crashes + crashed.sum(-1)
    counters = c._replace(step=step, hold=hold, crashes=crashes)
    frame = history_frame(sc, moved, alive)
    history = torch.cat([state["history"][:, 1:], frame[:, None]], dim=1)
    stepped = pack(moved, counters, f._replace(alive=alive), history)
    out = {
        "steps": step,
        "crashes": crashes,
        "alive": alive,
        "reward": reward,
        "evader_reward": evader_reward,
        "terminated": terminated,
        "truncated": truncated,
        "success": success,
        "crashed": crashed,
        "evader_contact": contact[:, -1],
        "distances": distances,
        "positions": torch.stack([x, y], dim=-1),
        "velocities": torch.stack([vx, vy], dim=-1),
    }
    return stepped, out


def step_core(
    sc: Scenario, state: dict[str, Tensor], actions: Tensor, evader_action: Tensor | None
) -> tuple[dict[str, Tensor], dict[str, Tensor]]:
    """:func:`advance` followed by :func:`observe` of the stepped state (no reset yet).

    Returns the stepped state and the outputs of :func:`advance` plus the views of
    :func:`observe` (``obs``, ``obs_mask``, ``state``, ``evader_obs``).
    """
    stepped, out = advance(sc, state, actions, evader_action)
    if sc.kernels and kernels.applies(stepped["vehicles"]):
        out.update(kernels.observe(sc, stepped["vehicles"], stepped["flags"][0]))
    else:
        v, _, f = unpack(stepped)
        out.update(observe(sc, v, f))
    return stepped, out


def reset_pass(
    sc: Scenario, state: dict[str, Tensor], views: dict[str, Tensor], pending: Tensor, capacity: int
) -> Tensor:
    """Auto-reset, in place: start the next episode of up to ``capacity`` of the ``pending``
    (E,) environments, overwriting their rows of ``state`` and of ``views`` (the observation
    tensors of :func:`observe`).

    Static shapes throughout (so that the pass compiles once): the first ``capacity`` pending
    environments are spawned and observed, then written back into their rows; slots left over
    (fewer than ``capacity`` pending) write back the rows they read, a no-op.

    Returns the environments still pending (E,) bool, for another pass.
    """
    order = torch.argsort((~pending).to(torch.int8), stable=True)[:capacity]  # pending first
    chosen = pending[order]  # (K,) which slots hold a pending environment
    c = Counters(*state["counters"].unbind(0))
    fresh = spawn(sc, c.key[order], c.episode[order] + 1)
    fv, _, ff = unpack(fresh)
    fresh_views = observe(sc, fv, ff)

    def write(target: Tensor, rows: Tensor, dim: int) -> None:
        shape = [1] * target.dim()
        shape[dim] = -1
        old = target.index_select(dim, order)
        target.index_copy_(dim, order, torch.where(chosen.view(shape), rows, old))

    for name, tensor in state.items():
        write(tensor, fresh[name], 0 if name == "history" else 1)
    for name in VIEW_KEYS:
        write(views[name], fresh_views[name], 0)
    taken = torch.zeros_like(pending).index_copy(0, order, chosen)
    return pending & ~taken

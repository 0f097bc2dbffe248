"""The Numba kernels of :mod:`pes.sim.kernels` for the rest of the step (imported on first use
only): the ``flee`` evader, the collisions, capture, rewards (:mod:`pes.sim.reward`'s terms,
compiled here with Numba's versions of their helpers) and history of
:func:`pes.sim.scenario.advance`, and :func:`pes.sim.scenario.observe`.

Each function walks the environments once and repeats the torch code's float32 arithmetic
operation by operation: every constant arrives as a float32 argument (torch rounds a Python
scalar to the tensor's dtype before it operates), ``s / t`` for a scalar ``s`` is
``(1 / t) * s`` (as torch's ``__rtruediv__``), minima and maxima keep the first index on ties.
``move`` covers the commands of the quadrotor model as well (the actions' clipping and the
attitude setpoint, :func:`pes.sim.dynamics.attitude_setpoint`), with the C library's ``atan``
and ``cos``. The results agree with the torch path's to float32 rounding (see
:mod:`pes.sim.kernels`).
"""

from __future__ import annotations

import numba
import numpy as np
from numba.extending import overload, register_jitable

from pes.sim import _numba_substeps as ss
from pes.sim import reward as terms

_ZERO, _ONE, _TWO = np.float32(0.0), np.float32(1.0), np.float32(2.0)
_INF, _BIG = np.float32(np.inf), np.float32(1e6)
_TINY_NORM, _MIN_DIST = np.float32(1e-9), np.float32(1e-3)
_CAP, _FORTY, _SOFTPLUS_LINEAR = np.float32(1.5), np.float32(40.0), np.float32(20.0)
_MIN_GAP, _GRAVITY = np.float32(1e-6), np.float32(9.81)
_EXP_ZERO = np.float32(-110.0)  # exp of less is below half the least float32: rounds to +0
_WALL_NX = np.array([1.0, -1.0, 0.0, 0.0], np.float32)  # the walls' normals: left, right,
_WALL_NY = np.array([0.0, 0.0, 1.0, -1.0], np.float32)  # bottom, top

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")  # IEEE division, as torch


# The rows of :func:`_block_contacts`'s block (ss.BLOCK vehicles, a row of ss.BLOCK numbers
# each, at these constant offsets in one flat array, as in ``ss.block_substeps``): position,
# velocity, 1 for a pursuer (0 for the evader); the nearest obstacle's distance and normal; the
# inward speed, the hit and touched flags (0 or 1), the push's two components, the nearest
# building's distance and normal, and the distances of the walls (left, right, bottom, top).
# The buildings' distances and normals are rows of three other arrays.
(_X, _Y, _VX, _VY, _PURSUER, _D, _NX, _NY, _INWARD, _HIT, _TOUCHED, _PUSH_X, _PUSH_Y) = (
    k * ss.BLOCK for k in range(13)
)
_BOX_D, _BOX_NX, _BOX_NY, _LEFT, _RIGHT, _BOTTOM, _TOP = (k * ss.BLOCK for k in range(13, 20))
_ROWS = 20


@_jit
def box_distance(px, py, cx, cy, hx, hy):
    """Signed distance and outward normal (x, y) of the building of centre (cx, cy) and half
    sizes (hx, hy) from (px, py) (:func:`pes.sim.geometry.obstacle_distances_xy`), without a
    branch."""
    rx, ry = px - cx, py - cy
    ex, ey = abs(rx) - hx, abs(ry) - hy
    sx = _ONE if rx >= _ZERO else -_ONE
    sy = _ONE if ry >= _ZERO else -_ONE
    ox = ex if ex > _ZERO else _ZERO
    oy = ey if ey > _ZERO else _ZERO
    out_len = np.sqrt(ox * ox + oy * oy)
    inner = ex if ex >= ey else ey
    inner = _ZERO if inner > _ZERO else inner
    inv = _ONE / (out_len if out_len > np.float32(1e-12) else np.float32(1e-12))
    along_x = ex >= ey
    nx = sx * ox * inv if out_len > _ZERO else (sx if along_x else _ZERO)
    ny = sy * oy * inv if out_len > _ZERO else (_ZERO if along_x else sy)
    return out_len + inner, nx, ny


@_jit
def _block_contacts(buf, box_d, box_nx, box_ny, count, boxes, width, height, radius, radius_gap):
    """The push out of the nearest obstacle of the first ``count`` vehicles of the block
    ``buf`` (rows above), in place: each obstacle's distance and normal (the buildings' into
    ``box_d``, ``box_nx``, ``box_ny`` (B, ss.BLOCK)), the nearest (with :func:`nearest`'s
    choice on ties), the push along its normal, the velocity then (a pursuer's zero, the
    evader's slid along the obstacle), the obstacles' distances after the push and whether
    one is still within ``radius`` (then ``collide`` resolves the vehicle on its own). Each
    loop runs over the block's vehicles, innermost and without a branch, so that LLVM
    vectorises it; per vehicle the operations and their order are those of one vehicle at a
    time (same bits)."""
    num_boxes = boxes.shape[0]
    for b in range(num_boxes):
        cx, cy, hx, hy = boxes[b, 0], boxes[b, 1], boxes[b, 2], boxes[b, 3]
        row_d, row_nx, row_ny = box_d[b], box_nx[b], box_ny[b]
        if b == 0:
            for j in range(count):
                d, nx, ny = box_distance(buf[_X + j], buf[_Y + j], cx, cy, hx, hy)
                row_d[j], row_nx[j], row_ny[j] = d, nx, ny
                buf[_BOX_D + j], buf[_BOX_NX + j], buf[_BOX_NY + j] = d, nx, ny
        else:
            for j in range(count):
                d, nx, ny = box_distance(buf[_X + j], buf[_Y + j], cx, cy, hx, hy)
                row_d[j], row_nx[j], row_ny[j] = d, nx, ny
                closer = d < buf[_BOX_D + j]
                buf[_BOX_D + j] = d if closer else buf[_BOX_D + j]
                buf[_BOX_NX + j] = nx if closer else buf[_BOX_NX + j]
                buf[_BOX_NY + j] = ny if closer else buf[_BOX_NY + j]
    for j in range(count):
        # The walls (left, right, bottom, top), then the nearest of walls and buildings.
        px, py = buf[_X + j], buf[_Y + j]
        left, right, bottom, top = px, width - px, py, height - py
        d, nx, ny = left, _ONE, _ZERO
        closer = right < d
        d, nx, ny = (right if closer else d), (-_ONE if closer else nx), (_ZERO if closer else ny)
        closer = bottom < d
        d, nx, ny = (bottom if closer else d), (_ZERO if closer else nx), (_ONE if closer else ny)
        closer = top < d
        d, nx, ny = (top if closer else d), (_ZERO if closer else nx), (-_ONE if closer else ny)
        if num_boxes > 0:
            closer = buf[_BOX_D + j] < d
            d = buf[_BOX_D + j] if closer else d
            nx = buf[_BOX_NX + j] if closer else nx
            ny = buf[_BOX_NY + j] if closer else ny
        # Push out of the nearest obstacle along its normal.
        hit = d < radius
        push = radius_gap - d if hit else _ZERO
        buf[_X + j], buf[_Y + j] = px + nx * push, py + ny * push
        buf[_D + j], buf[_NX + j], buf[_NY + j] = d + push, nx, ny
        vx, vy = buf[_VX + j], buf[_VY + j]
        inward = min(vx * nx + vy * ny, _ZERO)
        pursuer = buf[_PURSUER + j] != _ZERO
        slide_x, slide_y = vx - inward * nx, vy - inward * ny
        buf[_VX + j] = (_ZERO if pursuer else slide_x) if hit else vx
        buf[_VY + j] = (_ZERO if pursuer else slide_y) if hit else vy
        buf[_INWARD + j], buf[_HIT + j] = inward, _ONE if hit else _ZERO
        # The walls' distances after the push (as the buildings' below, normals and all).
        push_x, push_y = nx * push, ny * push
        buf[_PUSH_X + j], buf[_PUSH_Y + j] = push_x, push_y
        left = left + _ONE * push_x + _ZERO * push_y
        right = right + -_ONE * push_x + _ZERO * push_y
        bottom = bottom + _ZERO * push_x + _ONE * push_y
        top = top + _ZERO * push_x + -_ONE * push_y
        buf[_LEFT + j], buf[_RIGHT + j], buf[_BOTTOM + j], buf[_TOP + j] = left, right, bottom, top
        touched = (left < radius) | (right < radius) | (bottom < radius) | (top < radius)
        buf[_TOUCHED + j] = _ONE if touched else _ZERO
    for b in range(num_boxes):
        row_d, row_nx, row_ny = box_d[b], box_nx[b], box_ny[b]
        for j in range(count):
            d = row_d[j] + row_nx[j] * buf[_PUSH_X + j] + row_ny[j] * buf[_PUSH_Y + j]
            row_d[j] = d
            buf[_TOUCHED + j] = _ONE if d < radius else buf[_TOUCHED + j]


@_jit
def nearest(dist, num_boxes):
    """Index of the nearest obstacle in ``dist`` (B + 4,), with
    :func:`pes.sim.geometry.pick_nearest`'s choice on ties."""
    index = num_boxes
    for k in range(num_boxes + 1, num_boxes + 4):
        if dist[k] < dist[index]:
            index = k
    if num_boxes > 0:
        box = 0
        for k in range(1, num_boxes):
            if dist[k] < dist[box]:
                box = k
        if dist[box] < dist[index]:
            index = box
    return index


@_jit
def _per_axis(moves):
    """The largest move each way of ``moves`` (K,), combined (``scenario._per_axis``)."""
    top, bottom = moves[0], moves[0]
    for k in range(1, moves.shape[0]):
        if moves[k] > top:
            top = moves[k]
        if moves[k] < bottom:
            bottom = moves[k]
    return (top if top > _ZERO else _ZERO) + (bottom if bottom < _ZERO else _ZERO)


# Numba's versions of the helpers that pes.sim.reward's terms call (torch's are in reward.py):
# float32 in, float32 out, with torch's arithmetic.
@overload(terms.sqrt)
def _sqrt(x):
    return lambda x: np.sqrt(x)


@overload(terms.relu)
def _relu(x):
    zero = _ZERO if x == numba.types.float32 else 0.0
    return lambda x: zero if x < zero else x  # as torch's clamp: NaN and -0.0 kept


@overload(terms.softplus)
def _softplus(x):
    """torch's softplus: linear above 20; below -110 exp rounds to +0 and log1p(+0) is +0."""

    def impl(x):
        if x > _SOFTPLUS_LINEAR:
            return x
        if x < _EXP_ZERO:
            return _ZERO
        return np.log1p(np.exp(x))

    return impl


# The reward's terms, compiled where ``collide`` calls them.
for _term in (
    terms.softplus_obstacle_term,
    terms.lead_distance,
    terms.pursuer_reward,
    terms.evader_reward,
):
    register_jitable(error_model="numpy")(_term)


@_jit
def observe(vehicles, alive, other, width, height, vscale, e_vscale):
    """:func:`pes.sim.scenario.observe` of ``vehicles`` (16, E, A) and ``alive`` (E, N); returns
    obs (E, N, N, 8), obs_mask (E, N, N), state (E, A, 8) and evader_obs (E, A, 8)."""
    num_envs, n = alive.shape
    obs = np.zeros((num_envs, n, n, 8), np.float32)
    mask = np.zeros((num_envs, n, n), np.bool_)
    state = np.zeros((num_envs, n + 1, 8), np.float32)
    evader_obs = np.zeros((num_envs, n + 1, 8), np.float32)
    rows = np.empty((n, 8), np.float32)
    for e in range(num_envs):
        epx, epy = vehicles[0, e, n] / width, vehicles[1, e, n] / height
        eqx, eqy = vehicles[14, e, n] / width, vehicles[15, e, n] / height
        for i in range(n):
            px, py = vehicles[0, e, i] / width, vehicles[1, e, i] / height
            rows[i, 0], rows[i, 1] = px, py
            rows[i, 2], rows[i, 3] = vehicles[2, e, i] / vscale, vehicles[3, e, i] / vscale
            rows[i, 4], rows[i, 5] = vehicles[14, e, i] / width, vehicles[15, e, i] / height
            rows[i, 6], rows[i, 7] = epx - px, epy - py
        for i in range(n):
            for k in range(n):
                j = other[i, k]
                real = alive[e, j] and alive[e, i]
                mask[e, i, k] = real
                keep = _ONE if real else _ZERO
                for f in range(8):
                    value = rows[j, f]
                    if k > 0 and f < 4:  # rows of others: position and velocity relative to i
                        value = value - rows[i, f]
                    obs[e, i, k, f] = value * keep
            keep = _ONE if alive[e, i] else _ZERO
            for f in range(8):
                state[e, i, f] = rows[i, f] * keep
        state[e, n, 0], state[e, n, 1] = epx, epy
        state[e, n, 2], state[e, n, 3] = vehicles[2, e, n] / vscale, vehicles[3, e, n] / vscale
        state[e, n, 4], state[e, n, 5] = eqx, eqy
        # The evader's view: itself, with the vector to the nearest alive pursuer, then each.
        best, best_gap = 0, _INF
        for i in range(n):
            gap = rows[i, 6] * rows[i, 6] + rows[i, 7] * rows[i, 7] if alive[e, i] else _INF
            if gap < best_gap:
                best, best_gap = i, gap
        evx, evy = vehicles[2, e, n], vehicles[3, e, n]
        evader_obs[e, 0, 0], evader_obs[e, 0, 1] = epx, epy
        evader_obs[e, 0, 2], evader_obs[e, 0, 3] = evx / e_vscale, evy / e_vscale
        evader_obs[e, 0, 4], evader_obs[e, 0, 5] = eqx, eqy
        evader_obs[e, 0, 6], evader_obs[e, 0, 7] = -rows[best, 6], -rows[best, 7]
        for i in range(n):
            keep = _ONE if alive[e, i] else _ZERO
            row = evader_obs[e, 1 + i]
            row[0], row[1] = -rows[i, 6] * keep, -rows[i, 7] * keep
            row[2] = (vehicles[2, e, i] - evx) / e_vscale * keep
            row[3] = (vehicles[3, e, i] - evy) / e_vscale * keep
            row[4], row[5] = rows[i, 4] * keep, rows[i, 5] * keep
            row[6], row[7] = _ZERO * keep, _ZERO * keep
    return obs, mask, state, evader_obs


@_jit
def flee(vehicles, alive, rays, box_grown, box_centre, width_in, height_in, margin, p):
    """The ``flee`` evader's action (:class:`pes.sim.evader.FleeEvader`) for ``vehicles``
    (16, E, A) and ``alive`` (E, N).

    ``rays`` (M, 5): direction x, y, their reciprocals (1e-9 for a zero component) and 1 where
    the x component is zero, 2 where y is, 3 where both are (0 otherwise); ``box_grown`` (B, 4)
    the buildings grown by ``margin``; ``box_centre`` (B, 2); ``width_in``, ``height_in`` the
    arena's size less ``margin``. ``p`` (12,) float32: max speed, lookahead, threat radius
    squared, wall influence, wall repulsion, open space, escape, 0.3 * max accel, and spare.
    Returns ax, ay (E,) in [-1, 1]."""
    num_envs, n = alive.shape
    num_rays, num_boxes = rays.shape[0], box_grown.shape[0]
    max_speed, lookahead, threat2 = p[0], p[1], p[2]
    influence, repulsion, open_space, escape, accel = p[3], p[4], p[5], p[6], p[7]
    out_x = np.empty(num_envs, np.float32)
    out_y = np.empty(num_envs, np.float32)
    # the rays' columns, each contiguous, and per ray the numbers of the ray casts
    ux, uy = rays[:, 0].copy(), rays[:, 1].copy()
    inv_x, inv_y = rays[:, 2].copy(), rays[:, 3].copy()
    flat_x = (rays[:, 4] == 1) | (rays[:, 4] == 3)
    flat_y = (rays[:, 4] == 2) | (rays[:, 4] == 3)
    free = np.empty(num_rays, np.float32)
    t_min = np.empty(num_rays, np.float32)
    gap = np.empty(num_rays, np.float32)
    scores = np.empty(num_rays, np.float32)
    for e in range(num_envs):
        ex, ey = vehicles[0, e, n], vehicles[1, e, n]
        evx, evy = vehicles[2, e, n], vehicles[3, e, n]
        away_x, away_y = _ZERO, _ZERO
        for i in range(n):
            dx, dy = ex - vehicles[0, e, i], ey - vehicles[1, e, i]
            dist2 = dx * dx + dy * dy
            if dist2 < _ONE:
                dist2 = _ONE
            weight = (_ONE / (dist2 * np.sqrt(dist2))) * threat2 if alive[e, i] else _ZERO
            away_x = away_x + weight * dx
            away_y = away_y + weight * dy
        norm = np.sqrt(away_x * away_x + away_y * away_y)
        cap = (_ONE / (norm if norm > _TINY_NORM else _TINY_NORM)) * _CAP
        if cap > _ONE:
            cap = _ONE
        away_x, away_y = away_x * cap, away_y * cap
        d = vehicles[13, e, n]
        if d < _MIN_DIST:
            d = _MIN_DIST
        push = (influence - d) / influence
        if push < _ZERO:
            push = _ZERO
        push = push * push / d
        away_x = away_x - repulsion * push * vehicles[14, e, n]
        away_y = away_y - repulsion * push * vehicles[15, e, n]
        # Ray casts (pes.sim.geometry.ray_distance), all rays at once: the loops over the rays
        # are innermost and branch-free (selects; & and | rather than and and or), so that
        # LLVM vectorises them; each ray's operations and their order are those of one ray.
        for m in range(num_rays):
            wall_x = (width_in - ex) * inv_x[m] if ux[m] > _ZERO else (margin - ex) * inv_x[m]
            wall_y = (height_in - ey) * inv_y[m] if uy[m] > _ZERO else (margin - ey) * inv_y[m]
            wall_x = lookahead if flat_x[m] else wall_x
            wall_y = lookahead if flat_y[m] else wall_y
            dist = wall_x if wall_x <= wall_y else wall_y
            dist = _ZERO if dist < _ZERO else dist
            free[m] = lookahead if dist > lookahead else dist
            t_min[m] = _INF
        for b in range(num_boxes):
            x0, y0, x1, y1 = box_grown[b, 0], box_grown[b, 1], box_grown[b, 2], box_grown[b, 3]
            to_x, to_y = box_centre[b, 0] - ex, box_centre[b, 1] - ey
            for m in range(num_rays):
                tx0, tx1 = (x0 - ex) * inv_x[m], (x1 - ex) * inv_x[m]
                ty0, ty1 = (y0 - ey) * inv_y[m], (y1 - ey) * inv_y[m]
                t_enter = max(min(tx0, tx1), min(ty0, ty1))
                t_exit = min(max(tx0, tx1), max(ty0, ty1))
                hit = (t_enter <= t_exit) & (t_exit > _ZERO)
                towards = ux[m] * to_x + uy[m] * to_y > _ZERO
                hit = hit & ((not t_enter < _ZERO) | towards)
                t_hit = (t_enter if t_enter > _ZERO else _ZERO) if hit else lookahead
                t_min[m] = t_hit if t_hit < t_min[m] else t_min[m]
        if num_boxes > 0:
            for m in range(num_rays):
                free[m] = t_min[m] if t_min[m] < free[m] else free[m]
        # Each ray's smallest gap to an alive pursuer's position extrapolated to the time the
        # evader takes to run the ray's free length, then its score.
        for m in range(num_rays):
            gap[m] = _BIG
        for i in range(n):
            if alive[e, i]:
                px, py = vehicles[0, e, i], vehicles[1, e, i]
                pvx, pvy = vehicles[2, e, i], vehicles[3, e, i]
                for m in range(num_rays):
                    t = free[m] / max_speed
                    gx = (ex + ux[m] * free[m]) - (px + pvx * t)
                    gy = (ey + uy[m] * free[m]) - (py + pvy * t)
                    g = gx * gx + gy * gy
                    gap[m] = g if g < gap[m] else gap[m]
        for m in range(num_rays):
            score = ux[m] * away_x + uy[m] * away_y
            score = score + open_space * free[m] / lookahead
            root = np.sqrt(gap[m])
            score = score + escape * (root if root < _FORTY else _FORTY) / _FORTY
            scores[m] = score - _TWO * (_ONE if free[m] < _TWO else _ZERO)
        best, best_score = 0, -_INF
        for m in range(num_rays):
            if scores[m] > best_score or m == 0:
                best, best_score = m, scores[m]
        best_free = free[best] / np.float32(3.0)
        target_speed = max_speed * (best_free if best_free < _ONE else _ONE)
        ax = (rays[best, 0] * target_speed - evx) / accel
        ay = (rays[best, 1] * target_speed - evy) / accel
        norm = np.sqrt(ax * ax + ay * ay)
        if norm < _ONE:
            norm = _ONE
        out_x[e], out_y[e] = ax / norm, ay / norm
    return out_x, out_y


@_jit
def move(vehicles, actions, evader_ax, evader_ay, alive0, fx, fy, params, max_speed, p, n_sub):
    """The quadrotors' commands and dynamics of :func:`pes.sim.scenario.advance`: each pursuer's
    action (zero if dead) and the evader's, as accelerations clipped to the maximum, the
    attitude setpoints, and ``n_sub`` physics sub-steps.

    Args:
        vehicles: (16, E, A) the state. actions: (E, N, 2) in [-1, 1]. evader_ax, evader_ay:
            (E,). alive0: (E, N) bool. fx, fy: (E, A) disturbance forces (N), or (0, 0) for
            none. params: (5, A) max acceleration, mass and the gyroscopic ratios of roll, pitch
            and yaw. max_speed: (A,). p: (6,) float32 sub-step length, setpoint weight, kp, ki,
            kd, max tilt.

    Returns the first 13 fields after the step, (13, E, A), dead pursuers not yet held.
    """
    num_envs, n = alive0.shape
    num_vehicles = n + 1
    total = num_envs * num_vehicles
    h, b, kp, ki, kd, tilt = p[0], p[1], p[2], p[3], p[4], p[5]
    disturbed = fx.shape[0] > 0
    out = np.empty((13, num_envs, num_vehicles), np.float32)
    buf = np.empty(ss.ROWS * ss.BLOCK, np.float32)
    # Blocks of BLOCK (environment, vehicle) pairs in the order of the state: each vehicle's
    # commands (scalar: atan and cos are the C library's), then the sub-steps of the whole
    # block at once (vectorised, ss.block_substeps), then the block's results out.
    for start in range(0, total, ss.BLOCK):
        count = min(ss.BLOCK, total - start)
        for j in range(count):
            e, a = (start + j) // num_vehicles, (start + j) % num_vehicles
            if a < n:
                on = _ONE if alive0[e, a] else _ZERO
                ax, ay = actions[e, a, 0] * on, actions[e, a, 1] * on
            else:
                on = _ONE
                ax, ay = evader_ax[e], evader_ay[e]
            limit = params[0, a]
            ax, ay = ax * limit, ay * limit
            scale = limit * (_ONE / np.sqrt(ax * ax + ay * ay + np.float32(1e-12)))
            if scale > _ONE:
                scale = _ONE
            ax, ay = ax * scale, ay * scale
            pitch_ref = np.arctan(ax / _GRAVITY)
            pitch_ref = min(max(pitch_ref, -tilt), tilt)
            roll_ref = np.arctan(-ay * np.cos(pitch_ref) / _GRAVITY)
            roll_ref = min(max(roll_ref, -tilt), tilt)
            ex, ey = _ZERO, _ZERO
            if disturbed:
                ex, ey = fx[e, a] * on / params[1, a], fy[e, a] * on / params[1, a]
            ss.block_in(
                buf, j, vehicles, e, a, params[2, a], params[3, a], params[4, a], max_speed[a]
            )
            for k in range(3):
                buf[ss.COS_R + k * ss.BLOCK + j] = np.cos(vehicles[4 + k, e, a])
                buf[ss.SIN_R + k * ss.BLOCK + j] = np.sin(vehicles[4 + k, e, a])
            buf[ss.ROLL_REF + j], buf[ss.PITCH_REF + j] = roll_ref, pitch_ref
            buf[ss.EX + j], buf[ss.EY + j] = ex, ey
        ss.block_substeps(buf, count, h, b, kp, ki, kd, n_sub)
        ss.block_out(buf, count, start, out)
    return out


@_jit
def collide(
    vehicles,
    moved,
    alive0,
    damage_mask,
    counters,
    history,
    boxes,
    width,
    height,
    vscale,
    radius,
    radius_gap,
    capture_radius,
    capture_count,
    capture_hold,
    max_steps,
    disable,
    w,
):
    """The part of :func:`pes.sim.scenario.advance` after the dynamics: collisions, damage,
    capture, rewards (:mod:`pes.sim.reward`'s terms, per environment) and the history frame.

    Args:
        vehicles: (16, E, A) the state before the step; moved: (13, E, A) after the dynamics
            (dead pursuers not yet held in place). alive0, damage_mask: (E, N) bool.
        counters: (7, E) int64 (:class:`~pes.sim.scenario.Counters`). history: (E, H, A, 4).
        boxes: (B, 4) buildings as centre x, y and half size x, y.
        width, height: the arena (m); vscale: the history's velocity scale (m/s); radius,
            radius_gap: the body radius and the radius a contact pushes out to (m);
            capture_radius (m), capture_count, capture_hold, max_steps: the capture and episode
            rules; disable: crashes disable a pursuer; w: the reward's weights
            (:class:`pes.sim.reward.RewardWeights`; :class:`pes.sim.kernels.Constants` names
            the others).

    Returns the stepped vehicles (16, E, A), counters (7, E), alive (E, N), history, and the
    step's reward (E, N), evader reward (E,), terminated, truncated, success (E,), crashed
    (E, N), evader contact (E,), distances (E, N), positions and velocities (E, A, 2).
    """
    num_envs, n = alive0.shape
    num_vehicles, num_boxes = n + 1, boxes.shape[0]
    num_obstacles = num_boxes + 4

    out_v = np.empty_like(vehicles)
    out_c = counters.copy()
    alive = np.empty_like(alive0)
    out_h = np.empty_like(history)
    reward = np.empty((num_envs, n), np.float32)
    evader_reward = np.empty(num_envs, np.float32)
    terminated = np.empty(num_envs, np.bool_)
    truncated = np.empty(num_envs, np.bool_)
    success = np.empty(num_envs, np.bool_)
    crashed = np.empty((num_envs, n), np.bool_)
    evader_contact = np.empty(num_envs, np.bool_)
    distances = np.empty((num_envs, n), np.float32)
    positions = np.empty((num_envs, num_vehicles, 2), np.float32)
    velocities = np.empty((num_envs, num_vehicles, 2), np.float32)

    # Every (environment, vehicle) i = e * A + a in the order of the state: the dynamics'
    # fields for the active ones, the dead pursuers held where they were, at rest.
    total = num_envs * num_vehicles
    active = np.empty(total, np.bool_)
    for e in range(num_envs):
        for a in range(num_vehicles):
            active[e * num_vehicles + a] = a == n or alive0[e, a]
    moved_flat, before = moved.reshape(13, total), vehicles.reshape(16, total)
    out_flat = out_v.reshape(16, total)
    for f in range(13):
        for i in range(total):
            held = before[f, i] if f < 2 else _ZERO
            out_flat[f, i] = moved_flat[f, i] if active[i] else held
    at, speed = positions.reshape(total, 2), velocities.reshape(total, 2)
    contact = np.empty(total, np.bool_)
    dist = np.empty(total, np.float32)
    inward = np.empty(total, np.float32)

    # The contacts by blocks of ss.BLOCK vehicles (:func:`_block_contacts`), all obstacles of
    # the block at once; then the rare vehicle that touches a second obstacle on its own.
    buf = np.empty(_ROWS * ss.BLOCK, np.float32)
    box_d = np.empty((num_boxes, ss.BLOCK), np.float32)
    box_nx = np.empty((num_boxes, ss.BLOCK), np.float32)
    box_ny = np.empty((num_boxes, ss.BLOCK), np.float32)
    dists = np.empty(num_obstacles, np.float32)
    nxs = np.empty(num_obstacles, np.float32)
    nys = np.empty(num_obstacles, np.float32)
    moves = np.empty(num_obstacles, np.float32)
    inward_e = np.empty(num_obstacles, np.float32)
    nxs[num_boxes:], nys[num_boxes:] = _WALL_NX, _WALL_NY
    for start in range(0, total, ss.BLOCK):
        count = min(ss.BLOCK, total - start)
        for j in range(count):
            i = start + j
            buf[_X + j], buf[_Y + j] = out_flat[0, i], out_flat[1, i]
            buf[_VX + j], buf[_VY + j] = out_flat[2, i], out_flat[3, i]
            buf[_PURSUER + j] = _ONE if i % num_vehicles < n else _ZERO
        _block_contacts(buf, box_d, box_nx, box_ny, count, boxes, width, height, radius, radius_gap)
        for j in range(count):
            if buf[_TOUCHED + j] == _ZERO:
                continue
            # Out of every other obstacle still within the radius (resolve_contacts).
            for k in range(num_boxes):
                dists[k], nxs[k], nys[k] = box_d[k, j], box_nx[k, j], box_ny[k, j]
            dists[num_boxes], dists[num_boxes + 1] = buf[_LEFT + j], buf[_RIGHT + j]
            dists[num_boxes + 2], dists[num_boxes + 3] = buf[_BOTTOM + j], buf[_TOP + j]
            x, y, vx, vy = buf[_X + j], buf[_Y + j], buf[_VX + j], buf[_VY + j]
            for k in range(num_obstacles):
                moves[k] = nxs[k] * (radius_gap - dists[k] if dists[k] < radius else _ZERO)
            step_x = _per_axis(moves)
            for k in range(num_obstacles):
                moves[k] = nys[k] * (radius_gap - dists[k] if dists[k] < radius else _ZERO)
            step_y = _per_axis(moves)
            x, y = x + step_x, y + step_y
            over = dists < radius
            for k in range(num_obstacles):
                dists[k] = dists[k] + nxs[k] * step_x + nys[k] * step_y
            if buf[_PURSUER + j] != _ZERO:
                vx, vy = _ZERO, _ZERO
            else:
                for k in range(num_obstacles):
                    toward = min(vx * nxs[k] + vy * nys[k], _ZERO)
                    inward_e[k] = toward if over[k] else _ZERO
                for k in range(num_obstacles):
                    moves[k] = inward_e[k] * nxs[k]
                slide_x = vx - _per_axis(moves)
                for k in range(num_obstacles):
                    moves[k] = inward_e[k] * nys[k]
                vx, vy = slide_x, vy - _per_axis(moves)
            index = nearest(dists, num_boxes)
            buf[_X + j], buf[_Y + j], buf[_VX + j], buf[_VY + j] = x, y, vx, vy
            buf[_D + j], buf[_NX + j], buf[_NY + j] = dists[index], nxs[index], nys[index]
        for j in range(count):
            i = start + j
            x, y, vx, vy = buf[_X + j], buf[_Y + j], buf[_VX + j], buf[_VY + j]
            d, nx, ny = buf[_D + j], buf[_NX + j], buf[_NY + j]
            contact[i] = buf[_HIT + j] != _ZERO or buf[_TOUCHED + j] != _ZERO
            dist[i], inward[i] = d, buf[_INWARD + j]
            out_flat[0, i], out_flat[1, i], out_flat[2, i], out_flat[3, i] = x, y, vx, vy
            out_flat[13, i], out_flat[14, i], out_flat[15, i] = d, -nx * d, -ny * d
            at[i, 0], at[i, 1], speed[i, 0], speed[i, 1] = x, y, vx, vy

    for e in range(num_envs):
        base = e * num_vehicles
        step = counters[3, e] + 1
        damaged_now = step >= counters[6, e]
        ex, ey = out_v[0, e, n], out_v[1, e, n]
        near, alive_count, crash_count = 0, 0, 0
        alive0_any, nearest_gap = False, _INF
        for i in range(n):
            crashed[e, i] = contact[base + i] and alive0[e, i]
            crash_count += 1 if crashed[e, i] else 0
            on = alive0[e, i] and not (disable and crashed[e, i])
            alive[e, i] = on and not (damage_mask[e, i] and damaged_now)
            dx, dy = out_v[0, e, i] - ex, out_v[1, e, i] - ey
            distances[e, i] = np.sqrt(dx * dx + dy * dy)
            if distances[e, i] < capture_radius and alive[e, i]:
                near += 1
            alive_count += 1 if alive[e, i] else 0
            if alive0[e, i]:
                alive0_any = True
                if distances[e, i] < nearest_gap:
                    nearest_gap = distances[e, i]
        hold = counters[4, e] + 1 if near >= capture_count else 0
        success[e] = hold >= capture_hold
        terminated[e] = success[e] or alive_count < capture_count
        truncated[e] = step >= max_steps and not terminated[e]
        evader_contact[e] = contact[base + n]
        # Rewards: pes.sim.reward's terms, from this environment's distances and sums.
        paid_sum, unit_x, unit_y, count = _ZERO, _ZERO, _ZERO, _ZERO
        for i in range(n):
            a0 = _ONE if alive0[e, i] else _ZERO
            paid_sum = paid_sum + distances[e, i] * a0
            if w.encirclement != _ZERO:
                gap = distances[e, i] if distances[e, i] > _MIN_GAP else _MIN_GAP
                unit_x = unit_x + (out_v[0, e, i] - ex) / gap * a0
                unit_y = unit_y + (out_v[1, e, i] - ey) / gap * a0
                count = count + a0
        if count < _ONE:
            count = _ONE
        evx, evy = out_v[2, e, n], out_v[3, e, n]
        for i in range(n):
            charged = distances[e, i]
            if w.lead_on and not (alive0[e, i] and distances[e, i] == nearest_gap):
                dx, dy = out_v[0, e, i] - ex, out_v[1, e, i] - ey
                charged = terms.lead_distance(dx, dy, evx, evy, w)
            reward[e, i] = terms.pursuer_reward(
                w,
                paid_sum,
                charged,
                dist[base + i],
                inward[base + i],
                unit_x,
                unit_y,
                count,
                _ONE if crashed[e, i] else _ZERO,
                _ONE if success[e] else _ZERO,
                _ONE if alive0[e, i] else _ZERO,
            )
        evader_reward[e] = terms.evader_reward(
            w,
            nearest_gap if alive0_any else _ZERO,
            dist[base + n],
            _ONE if contact[base + n] else _ZERO,
            _ONE if success[e] else _ZERO,
        )
        out_c[3, e], out_c[4, e], out_c[5, e] = step, hold, counters[5, e] + crash_count

        frames = history.shape[1]
        for t in range(frames - 1):
            for a in range(num_vehicles):
                for f in range(4):
                    out_h[e, t, a, f] = history[e, t + 1, a, f]
        for a in range(num_vehicles):
            keep = _ONE if a == n or alive[e, a] else _ZERO
            out_h[e, frames - 1, a, 0] = out_v[0, e, a] / width * keep
            out_h[e, frames - 1, a, 1] = out_v[1, e, a] / height * keep
            out_h[e, frames - 1, a, 2] = out_v[2, e, a] / vscale * keep
            out_h[e, frames - 1, a, 3] = out_v[3, e, a] / vscale * keep

    return (
        out_v,
        out_c,
        alive,
        out_h,
        reward,
        evader_reward,
        terminated,
        truncated,
        success,
        crashed,
        evader_contact,
        distances,
        positions,
        velocities,
    )

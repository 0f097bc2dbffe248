"""The Numba kernel of :mod:`pes.sim.kernels` (imported on first use only): the quadrotor's
physics sub-steps, by blocks of vehicles and over every environment and vehicle, operation by
operation as :func:`pes.sim.dynamics.quadrotor_step` computes them in float32. Module-level
functions and constants, so that Numba's cache serves later processes."""

from __future__ import annotations

import numba
import numpy as np

_ONE, _HALF = np.float32(1.0), np.float32(0.5)
_C24, _C6, _C120 = np.float32(1.0 / 24.0), np.float32(1.0 / 6.0), np.float32(1.0 / 120.0)
_TINY, _GRAVITY = np.float32(1e-12), np.float32(9.81)

# A block of vehicles for :func:`block_substeps`: BLOCK vehicles in a flat float32 array of
# ROWS rows of BLOCK, one row per number, the row of a number starting at the offset named
# below: the 13 state numbers first, in the order of the state (position, velocity, attitude,
# rates, integrals), then the cos and sin of roll, pitch and yaw, the attitude setpoint, the
# external force per unit mass, the gyroscopic ratios and the maximum speed. One flat array
# with constant offsets, not a 2-D one, so that LLVM sees that the rows never overlap (a 2-D
# array's row length is a run-time number, and it does not vectorise a loop whose accesses
# it would have to check for overlap at run time, too many of them here).
BLOCK, ROWS = 64, 27
(X, Y, VX, VY, ROLL, PITCH, YAW, DROLL, DPITCH, DYAW, IROLL, IPITCH, IYAW) = (
    k * BLOCK for k in range(13)
)
COS_R, COS_P, COS_Y, SIN_R, SIN_P, SIN_Y = (k * BLOCK for k in range(13, 19))
ROLL_REF, PITCH_REF, EX, EY, G_ROLL, G_PITCH, G_YAW, VMAX = (k * BLOCK for k in range(19, 27))


@numba.njit(cache=True, nogil=True, error_model="numpy")  # IEEE division, as torch
def rotate(c, s, delta):
    """cos and sin of (angle + delta) from those of angle (:func:`pes.sim.dynamics._rotate`)."""
    d2 = delta * delta
    cd = _ONE - d2 * (_HALF - d2 * _C24)
    sd = delta * (_ONE - d2 * (_C6 - d2 * _C120))
    return c * cd - s * sd, s * cd + c * sd


@numba.njit(cache=True, nogil=True, error_model="numpy")  # IEEE division, as torch
def block_substeps(buf, count, h, b, kp, ki, kd, n):
    """``n`` sub-steps of the first ``count`` vehicles of the block ``buf`` (ROWS * BLOCK,), in
    place, sub-step after sub-step over the block. ``buf`` holds each vehicle's state, its
    trig (cos and sin of roll, pitch and yaw), attitude setpoint, external force per unit
    mass, gyroscopic ratios and maximum speed (rows as above); ``h`` the sub-step length,
    ``b``, ``kp``, ``ki``, ``kd`` the attitude PID (``attitude_gains``), all float32.

    Each vehicle's sub-steps are one chain of dependent operations, which a loop per vehicle
    runs at the latency of its divisions and square roots. Here the loop over the vehicles is
    innermost: its iterations are independent, and LLVM vectorises it (16 vehicles per AVX-512
    instruction; checked in the machine code, no packed instruction in the scalar version); a
    block small enough for the L1 cache keeps its loads and stores cheap. The body has no
    branch (the speed limit is a select) and repeats :func:`pes.sim.dynamics.quadrotor_step`'s
    operations in their order, as the per-vehicle loop did: no fast-math, so no reassociation
    nor fused multiply-add, and the vector division and square root are IEEE's, so the
    results are the same bits as one vehicle at a time."""
    for _ in range(n):
        for j in range(count):
            roll, pitch, yaw = buf[ROLL + j], buf[PITCH + j], buf[YAW + j]
            droll, dpitch, dyaw = buf[DROLL + j], buf[DPITCH + j], buf[DYAW + j]
            iroll, ipitch, iyaw = buf[IROLL + j], buf[IPITCH + j], buf[IYAW + j]
            rr, pr = buf[ROLL_REF + j], buf[PITCH_REF + j]
            e_roll, e_pitch, e_yaw = rr - roll, pr - pitch, -yaw
            acc_roll = buf[G_ROLL + j] * dpitch * dyaw + kp * (b * rr - roll) + ki * iroll
            acc_roll = acc_roll - kd * droll
            acc_pitch = buf[G_PITCH + j] * droll * dyaw + kp * (b * pr - pitch) + ki * ipitch
            acc_pitch = acc_pitch - kd * dpitch
            acc_yaw = buf[G_YAW + j] * dpitch * droll - kp * yaw + ki * iyaw - kd * dyaw
            buf[IROLL + j], buf[IPITCH + j] = iroll + e_roll * h, ipitch + e_pitch * h
            buf[IYAW + j] = iyaw + e_yaw * h
            droll = droll + acc_roll * h
            dpitch = dpitch + acc_pitch * h
            dyaw = dyaw + acc_yaw * h
            buf[DROLL + j], buf[DPITCH + j], buf[DYAW + j] = droll, dpitch, dyaw
            buf[ROLL + j], buf[PITCH + j] = roll + droll * h, pitch + dpitch * h
            buf[YAW + j] = yaw + dyaw * h
            cr, sr = rotate(buf[COS_R + j], buf[SIN_R + j], droll * h)
            cp, sp = rotate(buf[COS_P + j], buf[SIN_P + j], dpitch * h)
            cy, sy = rotate(buf[COS_Y + j], buf[SIN_Y + j], dyaw * h)
            buf[COS_R + j], buf[COS_P + j], buf[COS_Y + j] = cr, cp, cy
            buf[SIN_R + j], buf[SIN_P + j], buf[SIN_Y + j] = sr, sp, sy
            thrust_per_mass = (_ONE / (cr * cp)) * _GRAVITY
            ax = (sy * sr + cr * sp * cy) * thrust_per_mass + buf[EX + j]
            ay = (-cy * sr + cr * sp * sy) * thrust_per_mass + buf[EY + j]
            vx, vy = buf[VX + j] + ax * h, buf[VY + j] + ay * h
            scale = buf[VMAX + j] * (_ONE / np.sqrt(vx * vx + vy * vy + _TINY))
            scale = _ONE if scale > _ONE else scale
            vx, vy = vx * scale, vy * scale
            buf[VX + j], buf[VY + j] = vx, vy
            buf[X + j], buf[Y + j] = buf[X + j] + vx * h, buf[Y + j] + vy * h


@numba.njit(cache=True, nogil=True, error_model="numpy")
def block_in(buf, j, state, e, a, gyro_roll, gyro_pitch, gyro_yaw, vmax):
    """Vehicle (e, a) of ``state`` (at least 13, E, A) into slot ``j`` of the block ``buf``:
    its 13 state numbers, gyroscopic ratios and maximum speed (the other rows are the
    caller's)."""
    for f in range(13):
        buf[f * BLOCK + j] = state[f, e, a]
    buf[G_ROLL + j], buf[G_PITCH + j] = gyro_roll, gyro_pitch
    buf[G_YAW + j], buf[VMAX + j] = gyro_yaw, vmax


@numba.njit(cache=True, nogil=True, error_model="numpy")
def block_out(buf, count, start, out):
    """The 13 state numbers of the block's first ``count`` vehicles into ``out`` (13, E, A),
    vehicle j of the block at flat index ``start + j`` of (E, A)."""
    num_vehicles = out.shape[2]
    for j in range(count):
        e, a = (start + j) // num_vehicles, (start + j) % num_vehicles
        for f in range(13):
            out[f, e, a] = buf[f * BLOCK + j]


@numba.njit(cache=True, nogil=True, error_model="numpy")  # IEEE division, as torch
def substeps(state, trig, roll_ref, pitch_ref, fx, fy, gyro, max_speed, h, b, kp, ki, kd, n):
    """``n`` sub-steps of every (environment, vehicle); arguments as
    :func:`pes.sim.kernels.quadrotor_substeps` (trig: cos, then sin, of roll, pitch and yaw),
    by blocks of :func:`block_substeps`."""
    out = np.empty_like(state)
    num_envs, num_vehicles = roll_ref.shape
    total = num_envs * num_vehicles
    buf = np.empty(ROWS * BLOCK, np.float32)
    for start in range(0, total, BLOCK):
        count = min(BLOCK, total - start)
        for j in range(count):
            e, a = (start + j) // num_vehicles, (start + j) % num_vehicles
            block_in(buf, j, state, e, a, gyro[0, a], gyro[1, a], gyro[2, a], max_speed[a])
            for k in range(6):
                buf[COS_R + k * BLOCK + j] = trig[k, e, a]
            buf[ROLL_REF + j], buf[PITCH_REF + j] = roll_ref[e, a], pitch_ref[e, a]
            buf[EX + j], buf[EY + j] = fx[e, a], fy[e, a]
        block_substeps(buf, count, h, b, kp, ki, kd, n)
        block_out(buf, count, start, out)
    return out

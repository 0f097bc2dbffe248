"""The Numba kernel of :mod:`pes.sim.kernels` (imported on first use only): the quadrotor's
physics sub-steps, per vehicle and over every environment and vehicle, operation by operation
as :func:`pes.sim.dynamics.quadrotor_step` computes them in float32. Module-level functions and
constants, so that Numba's cache serves later processes."""

from __future__ import annotations

import numba
import numpy as np

_ONE, _HALF = np.float32(1.0), np.float32(0.5)
_C24, _C6, _C120 = np.float32(1.0 / 24.0), np.float32(1.0 / 6.0), np.float32(1.0 / 120.0)
_TINY, _GRAVITY = np.float32(1e-12), np.float32(9.81)


@numba.njit(cache=True, nogil=True, error_model="numpy")  # IEEE division, as torch
def rotate(c, s, delta):
    """cos and sin of (angle + delta) from those of angle (:func:`pes.sim.dynamics._rotate`)."""
    d2 = delta * delta
    cd = _ONE - d2 * (_HALF - d2 * _C24)
    sd = delta * (_ONE - d2 * (_C6 - d2 * _C120))
    return c * cd - s * sd, s * cd + c * sd


@numba.njit(cache=True, nogil=True, error_model="numpy")  # IEEE division, as torch
def vehicle_substeps(
    state, trig, rr, pr, ex, ey, g_roll, g_pitch, g_yaw, vmax, h, b, kp, ki, kd, n
):
    """``n`` sub-steps of one vehicle: ``state`` its 13 numbers (position, velocity, attitude,
    rates, integrals), ``trig`` cos and sin of its roll, pitch and yaw (6,), (rr, pr) its
    attitude setpoint, (ex, ey) the external force per unit mass; returns the 13 numbers after
    the sub-steps as a tuple."""
    x, y, vx, vy = state[0], state[1], state[2], state[3]
    roll, pitch, yaw = state[4], state[5], state[6]
    droll, dpitch, dyaw = state[7], state[8], state[9]
    iroll, ipitch, iyaw = state[10], state[11], state[12]
    cr, cp, cy, sr, sp, sy = trig[0], trig[1], trig[2], trig[3], trig[4], trig[5]
    for _ in range(n):
        e_roll, e_pitch, e_yaw = rr - roll, pr - pitch, -yaw
        acc_roll = g_roll * dpitch * dyaw + kp * (b * rr - roll) + ki * iroll
        acc_roll = acc_roll - kd * droll
        acc_pitch = g_pitch * droll * dyaw + kp * (b * pr - pitch) + ki * ipitch
        acc_pitch = acc_pitch - kd * dpitch
        acc_yaw = g_yaw * dpitch * droll - kp * yaw + ki * iyaw - kd * dyaw
        iroll, ipitch, iyaw = iroll + e_roll * h, ipitch + e_pitch * h, iyaw + e_yaw * h
        droll = droll + acc_roll * h
        dpitch = dpitch + acc_pitch * h
        dyaw = dyaw + acc_yaw * h
        roll, pitch, yaw = roll + droll * h, pitch + dpitch * h, yaw + dyaw * h
        cr, sr = rotate(cr, sr, droll * h)
        cp, sp = rotate(cp, sp, dpitch * h)
        cy, sy = rotate(cy, sy, dyaw * h)
        thrust_per_mass = (_ONE / (cr * cp)) * _GRAVITY
        ax = (sy * sr + cr * sp * cy) * thrust_per_mass + ex
        ay = (-cy * sr + cr * sp * sy) * thrust_per_mass + ey
        vx, vy = vx + ax * h, vy + ay * h
        scale = vmax * (_ONE / np.sqrt(vx * vx + vy * vy + _TINY))
        if scale > _ONE:
            scale = _ONE
        vx, vy = vx * scale, vy * scale
        x, y = x + vx * h, y + vy * h
    return x, y, vx, vy, roll, pitch, yaw, droll, dpitch, dyaw, iroll, ipitch, iyaw


@numba.njit(cache=True, nogil=True, error_model="numpy")  # IEEE division, as torch
def substeps(state, trig, roll_ref, pitch_ref, fx, fy, gyro, max_speed, h, b, kp, ki, kd, n):
    """``n`` sub-steps of every (environment, vehicle); arguments as
    :func:`pes.sim.kernels.quadrotor_substeps` (trig: cos, then sin, of roll, pitch and yaw)."""
    out = np.empty_like(state)
    num_envs, num_vehicles = roll_ref.shape
    for e in range(num_envs):
        for a in range(num_vehicles):
            moved = vehicle_substeps(
                state[:, e, a],
                trig[:, e, a],
                roll_ref[e, a],
                pitch_ref[e, a],
                fx[e, a],
                fy[e, a],
                gyro[0, a],
                gyro[1, a],
                gyro[2, a],
                max_speed[a],
                h,
                b,
                kp,
                ki,
                kd,
                n,
            )
            for f in range(13):
                out[f, e, a] = moved[f]
    return out

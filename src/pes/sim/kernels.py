"""Compiled CPU kernels for the hottest loop of the step: the quadrotor's physics sub-steps.

An eager torch step spends most of its time dispatching small operations (SPEC §6; measured in
docs/performance.md): the ten sub-steps of :func:`pes.sim.dynamics.quadrotor_step` alone are
some 700 tensor operations per control step. On the CPU, when torch is not compiling the step,
that loop runs here instead, as one Numba function that walks every (environment, vehicle)
once and keeps the whole sub-step loop in registers.

The kernel repeats :func:`~pes.sim.dynamics.quadrotor_step`'s float32 arithmetic operation by
operation, in the same order and with the same roundings (a scalar times a tensor rounds the
scalar to float32 first; ``g / t`` is ``(1 / t) * g``; ``rsqrt`` is ``1 / sqrt``), so both
paths give the same numbers bit for bit (tests/test_kernels.py). The transcendental functions
(the attitude setpoint's ``atan``, the initial ``cos`` and ``sin``) stay in torch.

Numba compiles the kernel on first use (about a second) and caches it beside this file.
``PES_KERNELS=0`` in the environment, or a missing ``numba``, selects the torch loop.
"""

from __future__ import annotations

import os

import numpy as np
import torch
from torch import Tensor

_ENABLED = os.environ.get("PES_KERNELS", "1") != "0"
_kernel = None  # the compiled sub-step loop, once loaded
_failed = False  # numba is missing or failed: use the torch loop


def available(t: Tensor) -> bool:
    """Whether :func:`quadrotor_substeps` serves tensors like ``t``: float32 on the CPU, no
    gradient, not under ``torch.compile``, and Numba importable (``PES_KERNELS`` not 0)."""
    return (
        _ENABLED
        and not _failed
        and t.device.type == "cpu"
        and t.dtype == torch.float32
        and not t.requires_grad
        and not torch.compiler.is_compiling()
        and _load() is not None
    )


def _load():
    """The compiled kernel (compiled or read from Numba's cache on first call), or None."""
    global _kernel, _failed
    if _kernel is None and not _failed:
        try:
            _kernel = _build()
        except Exception:  # noqa: BLE001 - no numba, or one that cannot compile: torch loop
            _failed = True
    return _kernel


def _build():
    import numba

    f32 = np.float32
    one, half, zero = f32(1.0), f32(0.5), f32(0.0)
    c24, c6, c120 = f32(1.0 / 24.0), f32(1.0 / 6.0), f32(1.0 / 120.0)
    tiny, gravity = f32(1e-12), f32(9.81)

    @numba.njit(cache=True, nogil=True)
    def rotate(c, s, delta):
        d2 = delta * delta
        cd = one - d2 * (half - d2 * c24)
        sd = delta * (one - d2 * (c6 - d2 * c120))
        return c * cd - s * sd, s * cd + c * sd

    @numba.njit(cache=True, nogil=True)
    def substeps(state, trig, roll_ref, pitch_ref, fx, fy, gyro, max_speed, h, b, kp, ki, kd, n):
        out = np.empty_like(state)
        num_envs, num_vehicles = roll_ref.shape
        for e in range(num_envs):
            for a in range(num_vehicles):
                x, y, vx, vy = state[0, e, a], state[1, e, a], state[2, e, a], state[3, e, a]
                roll, pitch, yaw = state[4, e, a], state[5, e, a], state[6, e, a]
                droll, dpitch, dyaw = state[7, e, a], state[8, e, a], state[9, e, a]
                iroll, ipitch, iyaw = state[10, e, a], state[11, e, a], state[12, e, a]
                cr, cp, cy = trig[0, e, a], trig[1, e, a], trig[2, e, a]
                sr, sp, sy = trig[3, e, a], trig[4, e, a], trig[5, e, a]
                rr, pr = roll_ref[e, a], pitch_ref[e, a]
                ex, ey = fx[e, a], fy[e, a]
                g_roll, g_pitch, g_yaw = gyro[0, a], gyro[1, a], gyro[2, a]
                vmax = max_speed[a]
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
                    thrust_per_mass = (one / (cr * cp)) * gravity
                    ax = (sy * sr + cr * sp * cy) * thrust_per_mass + ex
                    ay = (-cy * sr + cr * sp * sy) * thrust_per_mass + ey
                    vx, vy = vx + ax * h, vy + ay * h
                    scale = vmax * (one / np.sqrt(vx * vx + vy * vy + tiny))
                    if scale > one:
                        scale = one
                    vx, vy = vx * scale, vy * scale
                    x, y = x + vx * h, y + vy * h
                out[0, e, a], out[1, e, a], out[2, e, a], out[3, e, a] = x, y, vx, vy
                out[4, e, a], out[5, e, a], out[6, e, a] = roll, pitch, yaw
                out[7, e, a], out[8, e, a], out[9, e, a] = droll, dpitch, dyaw
                out[10, e, a], out[11, e, a], out[12, e, a] = iroll, ipitch, iyaw
        return out

    del zero
    return substeps


def quadrotor_substeps(
    state: Tensor,
    roll_ref: Tensor,
    pitch_ref: Tensor,
    fx: Tensor,
    fy: Tensor,
    gyro: Tensor,
    max_speed: Tensor,
    h: float,
    b: float,
    kp: float,
    ki: float,
    kd: float,
    substeps: int,
) -> Tensor:
    """The sub-step loop of :func:`pes.sim.dynamics.quadrotor_step` on the CPU.

    Args:
        state: (13, E, A) float32, the first 13 fields of :class:`~pes.sim.dynamics.Vehicles`
            (position m, velocity m/s, attitude rad, rates rad/s, integrals rad s).
        roll_ref, pitch_ref: (E, A) attitude setpoints, rad.
        fx, fy: (E, A) external force per unit mass, m/s^2.
        gyro: (3, A) the gyroscopic ratios of eq. (1) (roll, pitch, yaw).
        max_speed: (A,) m/s.
        h: sub-step length, s; b, kp, ki, kd: the attitude PID (see ``attitude_gains``).
        substeps: how many sub-steps.

    Returns:
        (13, E, A) float32, the state after ``substeps`` sub-steps.
    """
    kernel = _load()
    f32 = np.float32
    trig = torch.cat([torch.cos(state[4:7]), torch.sin(state[4:7])])
    out = kernel(
        state.contiguous().numpy(),
        trig.numpy(),
        roll_ref.contiguous().numpy(),
        pitch_ref.contiguous().numpy(),
        fx.contiguous().numpy(),
        fy.contiguous().numpy(),
        gyro.contiguous().numpy(),
        max_speed.contiguous().numpy(),
        f32(h),
        f32(b),
        f32(kp),
        f32(ki),
        f32(kd),
        int(substeps),
    )
    return torch.from_numpy(out)

"""Vehicle dynamics (paper §II-C): pure batched functions over (num_envs, num_vehicles) fields.

``quadrotor``: the policy's desired horizontal acceleration a_des is turned into desired roll
and pitch by inverting eq. (2) at yaw 0 with the thrust chosen so that z'' = 0 (the outer loop
of the cascade); an attitude PID (the inner loop) gives the moments Mx, My, Mz; eq. (1)
integrates the rotation and eq. (2) the translation. ``point_mass``: the acceleration is
applied directly. Both integrate with semi-implicit Euler and hold the speed to its limit.

The vehicle state is a :class:`Vehicles` of separate (E, A) tensors, one per component
(structure of arrays): every operation is then a flat, vectorisable loop over E * A numbers,
which is what lets ``torch.compile`` fuse a whole control step into a few tight loops.

Units: metres, seconds, radians, kilograms, newtons.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import torch
from torch import Tensor

from pes.sim import kernels

GRAVITY = 9.81  # m/s^2


class Vehicles(NamedTuple):
    """The state of every vehicle, each field (E, A): pursuers 0..N-1, then the evader."""

    x: Tensor  # position, m
    y: Tensor
    vx: Tensor  # velocity, m/s
    vy: Tensor
    roll: Tensor  # attitude, rad (quadrotor dynamics only)
    pitch: Tensor
    yaw: Tensor
    droll: Tensor  # attitude rates, rad/s
    dpitch: Tensor
    dyaw: Tensor
    iroll: Tensor  # integral of the attitude error, rad s (the PID's I term)
    ipitch: Tensor
    iyaw: Tensor
    obstacle_dist: Tensor  # signed distance to the nearest obstacle surface, m
    obstacle_dx: Tensor  # vector from the vehicle to the nearest obstacle point, m
    obstacle_dy: Tensor


@dataclass(frozen=True)
class VehicleParams:
    """Per-vehicle constants, each (A,) for A vehicles (pursuers, then evader)."""

    mass: Tensor  # kg
    max_speed: Tensor  # m/s
    max_accel: Tensor  # m/s^2
    ixx: Tensor  # moments of inertia, kg m^2
    iyy: Tensor
    izz: Tensor
    kp: float  # attitude proportional gain (1/s^2), per unit inertia
    ki: float  # attitude integral gain (1/s^3), per unit inertia
    kd: float  # attitude derivative gain (1/s), per unit inertia
    setpoint_weight: float  # share of the setpoint in the proportional term
    max_tilt: float  # rad


def attitude_gains(
    bandwidth: float, damping: float, integral_ratio: float = 0.1
) -> tuple[float, float, float, float]:
    """PID gains (kp, ki, kd), per unit inertia, and the setpoint weight b of the attitude loop.

    For J*theta'' = M with M = J*(kp*(b*r - theta) + ki*int(r - theta) - kd*theta'), the
    characteristic polynomial s^3 + kd s^2 + kp s + ki is placed at
    (s + a w)(s^2 + 2 z w s + w^2): a pair of natural frequency ``bandwidth`` (rad/s) and
    damping ``damping``, and a slow real pole at ``a w`` (``a`` = ``integral_ratio``) for the
    integral action. The weight b = 1 / (1 + 2 z a) puts the closed loop's zero on that slow
    pole, so that the response to the setpoint r is exactly w^2 / (s^2 + 2 z w s + w^2): no
    overshoot at z = 1, while the integral still rejects constant disturbance moments.
    """
    w, z, a = bandwidth, damping, integral_ratio
    return w * w * (1 + 2 * z * a), a * w**3, w * (2 * z + a), 1.0 / (1 + 2 * z * a)


def clip_norm(ax: Tensor, ay: Tensor, max_norm: Tensor) -> tuple[Tensor, Tensor]:
    """Scale the vectors (ax, ay) down to norm at most ``max_norm`` (all broadcast together)."""
    scale = torch.clamp(max_norm * torch.rsqrt(ax * ax + ay * ay + 1e-12), max=1.0)
    return ax * scale, ay * scale


def attitude_setpoint(ax: Tensor, ay: Tensor, max_tilt: float) -> tuple[Tensor, Tensor]:
    """Outer loop: desired (roll, pitch) for a desired acceleration (ax, ay) in m/s^2, yaw 0.

    Inverts eq. (2) at yaw 0 with F_z = m g / (cos(roll) cos(pitch)):
    x'' = g tan(pitch), y'' = -g tan(roll) / cos(pitch).
    """
    pitch = torch.atan(ax / GRAVITY).clamp(-max_tilt, max_tilt)
    roll = torch.atan(-ay * torch.cos(pitch) / GRAVITY).clamp(-max_tilt, max_tilt)
    return roll, pitch


def _rotate(c: Tensor, s: Tensor, delta: Tensor) -> tuple[Tensor, Tensor]:
    """cos and sin of (angle + delta) from those of angle, for a small increment ``delta``.

    The angle-addition identities with cos(delta), sin(delta) from their Taylor series, exact
    to float32 rounding for |delta| < 0.1 rad (a sub-step turns far less), replace two
    transcendental calls per angle and sub-step by a few multiplications.
    """
    d2 = delta * delta
    cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0))
    sd = delta * (1.0 - d2 * ((1.0 / 6.0) - d2 * (1.0 / 120.0)))
    return c * cd - s * sd, s * cd + c * sd


UNROLL = 2  # sub-steps per iteration of the compiled sub-step loop


def _repeat(body, state: tuple[Tensor, ...], times: int) -> tuple[Tensor, ...]:
    """``state = body(*state)`` ``times`` times.

    Under ``torch.compile`` this is a ``torch.while_loop`` over groups of ``UNROLL`` bodies:
    unrolling all ``times`` makes compilation minutes long, while a loop of single bodies
    pays the loop's overhead ``times`` times per step.
    """
    group = UNROLL if times % UNROLL == 0 else 1
    if torch.compiler.is_compiling() and hasattr(torch, "while_loop") and group < times:

        def grouped(i, *s):
            for _ in range(group):
                s = body(*s)
            return (i + 1, *s)

        counter = torch.zeros((), dtype=torch.int64, device=state[0].device)
        # The loop may not carry views of one another (the fields are views of one tensor).
        carried = tuple(t.clone() for t in state)
        out = torch.while_loop(lambda i, *s: i < times // group, grouped, (counter, *carried))
        return tuple(out[1:])
    for _ in range(times):
        state = body(*state)
    return state


def quadrotor_step(
    v: Vehicles,
    ax_cmd: Tensor,
    ay_cmd: Tensor,
    fx: Tensor,
    fy: Tensor,
    p: VehicleParams,
    dt: float,
    substeps: int,
    use_kernels: bool = False,
) -> Vehicles:
    """Advance the quadrotors by one control step of ``dt`` seconds in ``substeps`` sub-steps.

    Args:
        v: the vehicles, fields (E, A).
        ax_cmd, ay_cmd: desired horizontal acceleration (E, A), m/s^2, already clipped.
        fx, fy: external horizontal force (E, A), N, constant over the step.
        use_kernels: run the sub-steps in :mod:`pes.sim.kernels` (an environment that steps
            with them; tensors they cannot take still go through torch).

    Each sub-step: the attitude PID gives the moments
    M = J (kp (b ref - att) + ki int(ref - att) - kd rate) (see :func:`attitude_gains`);
    eq. (1) gives the angular accelerations (with its gyroscopic terms); eq. (2) with
    F_z = m g / (cos(roll) cos(pitch)) gives the horizontal acceleration, to which the external
    force adds; the speed is held to its limit. Returns the vehicles with new kinematics.
    """
    h = dt / substeps
    b = p.setpoint_weight
    roll_ref, pitch_ref = attitude_setpoint(ax_cmd, ay_cmd, p.max_tilt)
    gyro_roll = (p.iyy - p.izz) / p.ixx
    gyro_pitch = (p.izz - p.ixx) / p.iyy
    gyro_yaw = (p.ixx - p.iyy) / p.izz
    fx, fy = fx / p.mass, fy / p.mass
    max_speed = p.max_speed
    if use_kernels and kernels.applies(v.x):  # the same arithmetic, compiled
        gyro = torch.stack([gyro_roll, gyro_pitch, gyro_yaw])
        state = torch.stack(v[:13])
        out = kernels.quadrotor_substeps(
            state, roll_ref, pitch_ref, fx, fy, gyro, max_speed, h, b, p.kp, p.ki, p.kd, substeps
        )
        return Vehicles(*out.unbind(0), *v[13:])

    def substep(
        x,
        y,
        vx,
        vy,
        roll,
        pitch,
        yaw,
        droll,
        dpitch,
        dyaw,
        iroll,
        ipitch,
        iyaw,
        cr,
        sr,
        cp,
        sp,
        cy,
        sy,
    ):
        e_roll, e_pitch, e_yaw = roll_ref - roll, pitch_ref - pitch, -yaw
        # Eq. (1) with M / J from the PID (the inertia cancels).
        acc_roll = (
            gyro_roll * dpitch * dyaw + p.kp * (b * roll_ref - roll) + p.ki * iroll - p.kd * droll
        )
        acc_pitch = (
            gyro_pitch * droll * dyaw
            + p.kp * (b * pitch_ref - pitch)
            + p.ki * ipitch
            - p.kd * dpitch
        )
        acc_yaw = gyro_yaw * dpitch * droll - p.kp * yaw + p.ki * iyaw - p.kd * dyaw
        iroll, ipitch, iyaw = iroll + e_roll * h, ipitch + e_pitch * h, iyaw + e_yaw * h
        droll, dpitch, dyaw = droll + acc_roll * h, dpitch + acc_pitch * h, dyaw + acc_yaw * h
        roll, pitch, yaw = roll + droll * h, pitch + dpitch * h, yaw + dyaw * h
        cr, sr = _rotate(cr, sr, droll * h)
        cp, sp = _rotate(cp, sp, dpitch * h)
        cy, sy = _rotate(cy, sy, dyaw * h)
        # Eq. (2) at z'' = 0.
        thrust_per_mass = GRAVITY / (cr * cp)
        ax = (sy * sr + cr * sp * cy) * thrust_per_mass + fx
        ay = (-cy * sr + cr * sp * sy) * thrust_per_mass + fy
        vx, vy = clip_norm(vx + ax * h, vy + ay * h, max_speed)
        x, y = x + vx * h, y + vy * h
        return (
            x,
            y,
            vx,
            vy,
            roll,
            pitch,
            yaw,
            droll,
            dpitch,
            dyaw,
            iroll,
            ipitch,
            iyaw,
            cr,
            sr,
            cp,
            sp,
            cy,
            sy,
        )

    trig = (
        torch.cos(v.roll),
        torch.sin(v.roll),
        torch.cos(v.pitch),
        torch.sin(v.pitch),
        torch.cos(v.yaw),
        torch.sin(v.yaw),
    )
    out = _repeat(substep, (*v[:13], *trig), substeps)
    return Vehicles(*out[:13], *v[13:])


def point_mass_step(
    v: Vehicles,
    ax_cmd: Tensor,
    ay_cmd: Tensor,
    fx: Tensor,
    fy: Tensor,
    p: VehicleParams,
    dt: float,
    substeps: int,
) -> Vehicles:
    """Advance point masses by one control step; arguments as :func:`quadrotor_step`."""
    h = dt / substeps
    ax, ay = ax_cmd + fx / p.mass, ay_cmd + fy / p.mass

    def substep(x, y, vx, vy):
        vx, vy = clip_norm(vx + ax * h, vy + ay * h, p.max_speed)
        return x + vx * h, y + vy * h, vx, vy

    x, y, vx, vy = _repeat(substep, (v.x, v.y, v.vx, v.vy), substeps)
    return v._replace(x=x, y=y, vx=vx, vy=vy)

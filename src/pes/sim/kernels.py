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

The kernel itself is in :mod:`pes.sim._numba_substeps`, imported on first use only (so that
``import pes`` does not import Numba); Numba compiles it then (a few seconds) and caches the
machine code beside that file, so later processes load it. ``PES_KERNELS=0`` in the
environment, or a missing ``numba``, selects the torch loop.
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
            from pes.sim._numba_substeps import substeps

            # Compile (or load from the cache) now, for the argument types of every call, so
            # that a Numba that cannot compile means the torch loop, not an error mid-step.
            f32, grid, row = np.float32, np.zeros((1, 1), np.float32), np.ones(1, np.float32)
            cube = np.zeros((13, 1, 1), np.float32)
            trig = np.ones((6, 1, 1), np.float32)
            substeps(cube, trig, grid, grid, grid, grid, cube[:3, 0], row, *[f32(0.1)] * 5, 1)
            _kernel = substeps
        except Exception:  # noqa: BLE001 - no numba, or one that cannot compile: torch loop
            _failed = True
    return _kernel


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

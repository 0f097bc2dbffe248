"""Compiled CPU kernels for the step: the quadrotors' commands and physics sub-steps, the
``flee`` evader, the collisions, capture, rewards and history, and the observations.

An eager torch step spends most of its time dispatching small operations (measured in
docs/performance.md): some 1,000 tensor operations per control step, each costing microseconds
whatever its size. On the CPU, when torch is not compiling the step, those parts run here
instead, as Numba functions that walk every environment once and keep each vehicle's numbers
in registers, but for the physics sub-steps, the distances to the obstacles and the push out
of them, and the ``flee`` evader's ray casts, which run across blocks of vehicles and across
the rays so that LLVM vectorises them (same operations, same order, same bits).

The kernels repeat the torch code's float32 arithmetic operation by operation, in the same
order and with the same roundings (a scalar times a tensor rounds the scalar to float32 first;
``g / t`` is ``(1 / t) * g``; ``rsqrt`` is ``1 / sqrt``), so both paths agree to float32
rounding (tests/test_kernels.py): the kernels' square root is correctly rounded where torch's
vectorised one sometimes is not, and the attitude setpoint's ``atan`` and the softplus of
eq. (9) use the C library's. From the same state a step gives the same flags, captures,
crashes and resets on both paths; trajectories drift apart by rounding over many steps. The
disturbance (counter-based random numbers) and the network evader stay in torch.

The kernels are in :mod:`pes.sim._numba_substeps` and :mod:`pes.sim._numba_step`, imported on
first use only (so that ``import pes`` does not import Numba). Numba compiles them once per
machine (some 20-35 s on a 2-core machine) and caches the machine code (beside those files, or in
``NUMBA_CACHE_DIR``); a file ``pes-kernels-<key>.ready`` there says that a compilation
finished for these sources, this Python and this Numba (a compilation for sources without one
first removes the cached code of those files, as Numba keys each function on its own file only:
:func:`clear_cache`). When the first step finds no such file it does not wait: a background
process compiles the kernels while that environment steps in torch; an environment chooses its
path once, when it is made (:func:`usable`), so a run never switches mid-way, and environments
made after the compilation use the kernels. :func:`wait` loads them first, compiling them if
need be: evaluations, trainings, ``pes bench`` and the demo call it, so that their figures
never depend on when a compilation finished. ``PES_KERNELS=0`` in the environment, or a
missing ``numba``, selects the torch code.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.metadata
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch
from torch import Tensor

from pes.sim.reward import RewardWeights

_ENABLED = os.environ.get("PES_KERNELS", "1") != "0"
_step = None  # the module of the step's kernels, once loaded
_failed = False  # numba is missing or failed: use the torch code
_child: subprocess.Popen | None = None  # the background compilation this process started
_next_look = 0.0  # time.monotonic() of the next look at the background compilation
_LOOK_EVERY = 0.5  # seconds between looks
_SOURCES = ("_numba_step.py", "_numba_substeps.py", "reward.py")
"""The files the kernels are compiled from (``_numba_step`` compiles reward.py's terms)."""
_CACHED = ("_numba_step", "_numba_substeps")
"""The modules whose functions Numba caches (reward.py's terms are cached inside theirs)."""


def usable(device: torch.device) -> bool:
    """Whether an environment made now on ``device`` steps with the kernels, for its whole
    life: on the CPU, Numba importable (``PES_KERNELS`` not 0) and the kernels compiled. Where
    they are not compiled yet this starts their compilation in the background (or looks at it)
    and says no: that environment steps in torch, and those made once it is done use them."""
    global _next_look
    if not _ENABLED or _failed or torch.device(device).type != "cpu":
        return False
    _next_look = 0.0  # look at a background compilation now
    return _load() is not None


def applies(t: Tensor) -> bool:
    """Whether the kernels can take tensors like ``t`` (of an environment that uses them):
    float32, no gradient, not under ``torch.compile``."""
    return (
        t.device.type == "cpu"
        and t.dtype == torch.float32
        and not t.requires_grad
        and not torch.compiler.is_compiling()
    )


def serving() -> bool:
    """Whether the kernels are loaded in this process (the steps that can use them do)."""
    return _step is not None


def wait() -> bool:
    """Load the kernels now, compiling them here if no compilation is cached (or waiting for
    the background one); returns whether they serve (False: ``PES_KERNELS=0``, no Numba, or
    a Numba that cannot compile them)."""
    if _ENABLED and _step is None and not _failed:
        if _child is not None:
            _child.wait()
        _compile_here()
    return _step is not None


def ready_marker() -> Path:
    """The file that says the kernels of these sources are compiled and cached for this
    Python, Numba and machine type (it holds no code: Numba's cache does). Its name is keyed
    as Numba keys its cache: the sources' path, modification time and size, and their
    contents, Python's and Numba's versions and the machine type. Raises
    ``importlib.metadata.PackageNotFoundError`` where Numba is not installed."""
    key = hashlib.sha1()
    here = Path(__file__).resolve().parent
    for name in _SOURCES:
        source = here / name
        facts = source.stat()
        key.update(f"{source} {facts.st_mtime_ns} {facts.st_size}".encode())
        key.update(source.read_bytes())
    numba_version = importlib.metadata.version("numba")
    key.update(f"{sys.version_info[:2]} {platform.machine()} {numba_version}".encode())
    folder = os.environ.get("NUMBA_CACHE_DIR")
    if folder:
        root = Path(folder)
    elif os.access(here, os.W_OK):
        root = here / "__pycache__"  # where Numba caches them too
    else:  # a read-only installation: Numba caches in the user's folder
        root = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "pes"
    return root / f"pes-kernels-{key.hexdigest()[:16]}.ready"


def _cache_folders() -> set[Path]:
    """The folders where Numba caches the machine code of the kernels' modules (beside them
    in ``__pycache__``, under ``NUMBA_CACHE_DIR`` or in the user's folder), as Numba's own
    cache of each module's functions says; imports Numba."""
    from pes.sim import _numba_step, _numba_substeps

    try:
        return {Path(f._cache.cache_path) for f in (_numba_step.collide, _numba_substeps.substeps)}
    except AttributeError:  # a Numba that keeps it elsewhere: nothing found to clear
        return set()


def clear_cache(folders) -> None:
    """Remove Numba's cached machine code of the kernels' modules (the index ``.nbi`` and data
    ``.nbc`` files of ``_numba_step`` and ``_numba_substeps``) from ``folders``, and nothing
    else. Numba keys a function's cache on its own source file only: ``move`` in
    _numba_step.py inlines ``block_substeps`` of _numba_substeps.py, ``collide`` the reward's
    terms of reward.py, and each would load the machine code of the old functions after a
    change of that file alone. So a compilation for sources with no ready marker
    (:func:`ready_marker` keys on all three files) first clears both modules' cache, and
    compiles every kernel anew."""
    for folder in folders:
        for module in _CACHED:
            for pattern in (f"{module}.*.nbi", f"{module}.*.nbc"):
                for path in Path(folder).glob(pattern):
                    # another process may have removed it first
                    with contextlib.suppress(OSError):
                        path.unlink()


def _marked() -> bool:
    """Whether a compilation of these sources is marked ready (:func:`ready_marker`); True
    where there is no mark to look for (then the kernels load or compile in this process, as
    :func:`wait` does, and no cached code is cleared)."""
    try:
        return ready_marker().is_file()
    except (OSError, importlib.metadata.PackageNotFoundError):
        return True


def _load():
    """The module of the step's kernels if they serve now, else None: loaded from the cache
    when a compilation is marked ready, otherwise a background compilation started (or
    looked at, every half second) and None meanwhile."""
    global _child, _next_look, _failed
    if _step is not None or _failed:
        return _step
    now = time.monotonic()
    if now < _next_look:
        return None
    _next_look = now + _LOOK_EVERY
    if _child is not None:  # this process's background compilation
        code = _child.poll()
        if code == 0:
            _compile_here()  # from the cache it filled
        elif code is not None:  # it failed: Numba cannot compile them here either
            _failed = True
        return _step
    if _marked():
        _compile_here()
        return _step
    try:
        _child = subprocess.Popen(
            [sys.executable, "-c", "from pes.sim import kernels; kernels._compile_all()"],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            # the child imports pes as this process does (a path added at run time too)
            env={**os.environ, "PYTHONPATH": os.pathsep.join(p or "." for p in sys.path)},
        )
    except OSError:
        _compile_here()
    return _step


def _compile_here() -> None:
    """Load the kernels in this process (Numba reads its cache or compiles), for the argument
    types of every call, so that a Numba that cannot compile means the torch code, not an
    error mid-step; then mark them ready."""
    global _step, _failed
    if _step is not None or _failed:
        return
    marked = _marked()
    try:
        from pes.sim import _numba_step
        from pes.sim._numba_substeps import substeps

        if not marked:  # new sources: none of the cached machine code may serve
            clear_cache(_cache_folders())
        f32 = np.float32
        vehicles, cube = np.ones((16, 1, 2), np.float32), np.zeros((13, 1, 2), np.float32)
        alive = np.ones((1, 1), np.bool_)
        boxes = np.ones((1, 4), np.float32)
        _numba_step.observe(vehicles, alive, np.zeros((1, 1), np.int64), *[f32(1)] * 4)
        rays = np.ones((1, 5), np.float32)
        consts = np.ones(12, np.float32)
        _numba_step.flee(vehicles, alive, rays, boxes, boxes[:, :2], *[f32(1)] * 3, consts)
        actions, axes = np.zeros((1, 1, 2), np.float32), np.zeros(1, np.float32)
        params, none = np.ones((5, 2), np.float32), np.zeros((0, 0), np.float32)
        speeds = np.ones(2, np.float32)
        _numba_step.move(
            vehicles, actions, axes, axes, alive, none, none, params, speeds, consts[:6], 1
        )
        counters = np.ones((7, 1), np.int64)
        history = np.zeros((1, 2, 2, 4), np.float32)
        rules = (f32(1),) * 6 + (1, 1, 1, True)
        weights = RewardWeights(*(f32(1),) * 6, True, *(f32(1),) * 8)
        _numba_step.collide(vehicles, cube, alive, alive, counters, history, boxes, *rules, weights)
        # the sub-step kernel of the physics outside a full step (quadrotor_substeps)
        one, state = np.ones((1, 1), np.float32), np.zeros((13, 1, 1), np.float32)
        trig, gyro = np.ones((6, 1, 1), np.float32), np.zeros((3, 1), np.float32)
        substeps(state, trig, one, one, one, one, gyro, np.ones(1, np.float32), *[f32(1)] * 5, 1)
    except Exception:  # noqa: BLE001 - no numba, or one that cannot compile: torch code
        _failed = True
        return
    _step = _numba_step
    try:
        marker = ready_marker()
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.touch()
    except (OSError, importlib.metadata.PackageNotFoundError):  # later processes load it here
        pass


def _compile_all() -> None:
    """The background compilation (a child process): the kernels into Numba's cache and the
    ready mark; exits with status 1 where they cannot be compiled."""
    _compile_here()
    if _step is None:
        sys.exit(1)


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
    from pes.sim._numba_substeps import substeps as kernel

    f32 = np.float32
    trig = torch.cat([torch.cos(state[4:7]), torch.sin(state[4:7])])
    out = kernel(
        _numpy(state),
        trig.numpy(),
        _numpy(roll_ref),
        _numpy(pitch_ref),
        _numpy(fx),
        _numpy(fy),
        _numpy(gyro),
        _numpy(max_speed),
        f32(h),
        f32(b),
        f32(kp),
        f32(ki),
        f32(kd),
        int(substeps),
    )
    return torch.from_numpy(out)


COLLIDE_OUTPUTS = (
    "reward",
    "evader_reward",
    "terminated",
    "truncated",
    "success",
    "crashed",
    "evader_contact",
    "distances",
    "positions",
    "velocities",
)
"""The outputs of :func:`pes.sim._numba_step.collide` after the state, in its order."""


def _numpy(t: Tensor) -> np.ndarray:
    """A CPU tensor as a C-contiguous NumPy array, without a copy where it already is one."""
    return t.contiguous().numpy()


class Constants(NamedTuple):
    """A scenario's constants as the kernels take them (NumPy, float32 unless said), built once
    per :class:`~pes.sim.scenario.Scenario` with the same float32 operations as the torch
    code."""

    vehicle_params: np.ndarray
    """(5, A): max acceleration, mass and the three gyroscopic factors of eq. (1)."""
    dynamics: np.ndarray
    """(6,): the sub-step (s), the setpoint weight, kp, ki, kd and the maximum tilt (rad)."""
    no_force: np.ndarray
    """(0, 0): the disturbance's place when it is off."""
    boxes: np.ndarray
    """(B, 4): the buildings as centre x, y and half size x, y (m)."""
    other: np.ndarray
    """(N, N) int64: row k of pursuer i's observation shows pursuer ``other[i, k]``."""
    width: np.float32
    """The arena's width (m)."""
    height: np.float32
    """The arena's height (m)."""
    vscale: np.float32
    """The pursuers' velocity scale of the observations and the history (m/s)."""
    e_vscale: np.float32
    """The evader's velocity scale of its observation (m/s)."""
    radius: np.float32
    """The body radius (m): a vehicle closer to an obstacle touches it."""
    radius_gap: np.float32
    """The distance a contact pushes a vehicle out to (m)."""
    capture_radius: np.float32
    """(m) of the capture rule."""
    capture_count: int
    """Pursuers within the capture radius that a capture needs."""
    capture_hold: int
    """Steps they must hold it."""
    max_steps: int
    """The step limit of an episode."""
    disable: bool
    """Crashes disable a pursuer (``crash_mode="disable"``)."""
    reward: RewardWeights
    """The reward's constants."""


def _constants(sc) -> Constants:
    """The kernels' :class:`Constants` of ``sc`` (built on first use, then kept on it)."""
    consts = sc.kernel_constants
    if consts is not None:
        return consts
    from pes.sim.scenario import CONTACT_GAP

    cfg, boxes, f32 = sc.config, sc.boxes, np.float32
    centre_x, centre_y = (boxes[:, 0] + boxes[:, 2]) * 0.5, (boxes[:, 1] + boxes[:, 3]) * 0.5
    half_x, half_y = (boxes[:, 2] - boxes[:, 0]) * 0.5, (boxes[:, 3] - boxes[:, 1]) * 0.5
    p = sc.params
    dynamics = [p.max_accel, p.mass]
    dynamics += [(p.iyy - p.izz) / p.ixx, (p.izz - p.ixx) / p.iyy, (p.ixx - p.iyy) / p.izz]
    step = [cfg.dt / cfg.physics_substeps, p.setpoint_weight, p.kp, p.ki, p.kd, p.max_tilt]
    consts = Constants(
        vehicle_params=torch.stack(dynamics).contiguous().numpy(),
        dynamics=np.array(step, np.float32),
        no_force=np.zeros((0, 0), np.float32),
        boxes=torch.stack([centre_x, centre_y, half_x, half_y], -1).contiguous().numpy(),
        other=sc.other_index.contiguous().numpy(),
        width=f32(sc.arena[0].item()),
        height=f32(sc.arena[1].item()),
        vscale=f32(sc.vel_scale),
        e_vscale=f32(cfg.evader_max_speed),
        radius=f32(cfg.body_radius),
        radius_gap=f32(cfg.body_radius + CONTACT_GAP),
        capture_radius=f32(cfg.capture_radius),
        capture_count=cfg.capture_count,
        capture_hold=cfg.capture_hold,
        max_steps=cfg.max_steps,
        disable=cfg.crash_mode == "disable",
        reward=sc.reward_weights.as_float32(),
    )
    sc.kernel_constants = consts
    return consts


def observe(sc, vehicles: Tensor, alive: Tensor) -> dict[str, Tensor]:
    """:func:`pes.sim.scenario.observe` of the packed ``vehicles`` (16, E, A) and ``alive``
    (E, N): the same dict of views, computed by one kernel call."""
    k = _constants(sc)
    obs, mask, state, evader_obs = _step.observe(
        _numpy(vehicles), _numpy(alive), k.other, k.width, k.height, k.vscale, k.e_vscale
    )
    return {
        "obs": torch.from_numpy(obs),
        "obs_mask": torch.from_numpy(mask),
        "state": torch.from_numpy(state),
        "evader_obs": torch.from_numpy(evader_obs),
    }


def move_quadrotors(
    sc,
    vehicles: Tensor,
    actions: Tensor,
    evader_ax: Tensor,
    evader_ay: Tensor,
    alive0: Tensor,
    force: tuple[Tensor, Tensor] | None,
) -> Tensor:
    """The quadrotors' commands and physics sub-steps of :func:`pes.sim.scenario.advance` by
    one kernel call: ``vehicles`` (16, E, A), ``actions`` (E, N, 2) in [-1, 1], the evader's
    action ``evader_ax``, ``evader_ay`` (E,), ``alive0`` (E, N), ``force`` the disturbance
    (fx, fy) (E, A) in newtons or None. Returns the first 13 fields after the step,
    (13, E, A)."""
    k = _constants(sc)
    fx, fy = (k.no_force, k.no_force) if force is None else (f.numpy() for f in force)
    moved = _step.move(
        _numpy(vehicles),
        _numpy(actions),
        _numpy(evader_ax),
        _numpy(evader_ay),
        _numpy(alive0),
        fx,
        fy,
        k.vehicle_params,
        sc.params.max_speed.numpy(),
        k.dynamics,
        sc.config.physics_substeps,
    )
    return torch.from_numpy(moved)


def flee(evader, vehicles: Tensor, alive: Tensor) -> tuple[Tensor, Tensor]:
    """:class:`pes.sim.evader.FleeEvader`'s action for the packed ``vehicles`` (16, E, A) and
    ``alive`` (E, N): ax, ay (E,) in [-1, 1], by one kernel call."""
    k = evader.kernel_constants
    if k is None:
        f32, margin = np.float32, evader.margin
        d = evader.directions
        tiny = d.abs() < 1e-9
        inv = 1.0 / torch.where(tiny, 1e-9, d)
        flat = tiny[:, 0].float() + 2 * tiny[:, 1].float()
        boxes = evader.boxes
        grown = torch.stack(
            [
                boxes[:, 0] - margin,
                boxes[:, 1] - margin,
                boxes[:, 2] + margin,
                boxes[:, 3] + margin,
            ],
            -1,
        )
        centre = torch.stack(
            [(boxes[:, 0] + boxes[:, 2]) * 0.5, (boxes[:, 1] + boxes[:, 3]) * 0.5], -1
        )
        consts = [
            evader.max_speed,
            evader.lookahead,
            evader.threat_radius**2,
            evader.wall_influence,
            evader.wall_repulsion,
            evader.open_space,
            evader.escape,
            0.3 * evader.max_accel,
        ]
        k = {
            "rays": torch.cat([d, inv, flat[:, None]], -1).contiguous().numpy(),
            "grown": grown.reshape(-1, 4).contiguous().numpy(),
            "centre": centre.reshape(-1, 2).contiguous().numpy(),
            "width_in": f32((evader.arena[0] - margin).item()),
            "height_in": f32((evader.arena[1] - margin).item()),
            "margin": f32(margin),
            "floats": np.array(consts + [0.0] * (12 - len(consts)), np.float32),
        }
        evader.kernel_constants = k
    ax, ay = _step.flee(
        _numpy(vehicles),
        _numpy(alive),
        k["rays"],
        k["grown"],
        k["centre"],
        k["width_in"],
        k["height_in"],
        k["margin"],
        k["floats"],
    )
    return torch.from_numpy(ax), torch.from_numpy(ay)


def collide(
    sc, state: dict[str, Tensor], moved: Tensor
) -> tuple[dict[str, Tensor], dict[str, Tensor]]:
    """The rest of :func:`pes.sim.scenario.advance` once the dynamics have moved the vehicles:
    ``state`` is the packed state before the step, ``moved`` (13, E, A) the dynamics' first 13
    fields. Returns ``advance``'s stepped state and outputs."""
    k = _constants(sc)
    flags = state["flags"]
    arrays = _step.collide(
        *(_numpy(t) for t in (state["vehicles"], moved, flags[0], flags[1])),
        *(_numpy(state[key]) for key in ("counters", "history")),
        k.boxes,
        k.width,
        k.height,
        k.vscale,
        k.radius,
        k.radius_gap,
        k.capture_radius,
        k.capture_count,
        k.capture_hold,
        k.max_steps,
        k.disable,
        k.reward,
    )
    vehicles, counters, alive, history, *rest = (torch.from_numpy(a) for a in arrays)
    stepped = {
        "vehicles": vehicles,
        "counters": counters,
        "flags": torch.stack([alive, flags[1]]),
        "history": history,
    }
    out = {"steps": counters[3].clone(), "crashes": counters[5].clone(), "alive": alive}
    out.update(zip(COLLIDE_OUTPUTS, rest))
    return stepped, out

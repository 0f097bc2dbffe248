"""``EnvConfig``: every setting of the pursuit-evasion scenario (docs/scenario.md, paper §II).

Defaults follow the paper where it gives a number and ``docs/scenario.md`` where it does not.
Units are SI (metres, seconds, kilograms) unless a field says otherwise.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from pes.errors import ConfigError
from pes.strict import check_types, from_dict, load_yaml, parse_override, strict_keywords

Dynamics = Literal["quadrotor", "point_mass"]
CrashMode = Literal["continue", "disable"]
EVADER_POLICIES = ("flee", "random", "ddpg", "external")
SHIPPED_EVADERS = ("evader-ddpg-paper", "evader-ddpg")
"""Names of the DDPG evaders shipped with PES (``evader_model``): the one calibrated to the
paper's (PID(PF) captures it about as often as the paper's PID(PF) caught its evader, 27.3 %)
and the fully trained one (docs/algorithms/evader_ddpg.md)."""

MAX_ARENA = 1000.0
"""Largest arena side (m) that ``validate`` accepts (the start regions are found on a grid of
0.5 m cells)."""

REWARD_KEYS = (
    "cooperation_weight",
    "self_weight",
    "safe_distance",
    "softplus_k",
    "crash_reward",
    "capture_reward",
    "encirclement_weight",
    "intercept_lead",
    "distance_metric",
    "approach_weight",
    "approach_decel",
    "evader_capture_reward",
    "evader_crash_reward",
)
"""Scenario keys that only shape the reward: a training run may change them, every evaluation
(:meth:`EnvConfig.for_evaluation`) resets them to the paper's values."""


@strict_keywords
@dataclass
class EnvConfig:
    """The pursuit-evasion scenario. Build with ``EnvConfig(...)``, ``EnvConfig.from_dict`` or
    ``EnvConfig.from_yaml``; ``validate()`` raises :class:`pes.errors.ConfigError` on any
    impossible value."""

    # --- agents -------------------------------------------------------------------------
    num_pursuers: int = 5
    """Number of pursuers N (any N >= 1). They are named ``pursuer_0`` ... ``pursuer_{N-1}``."""
    evader_policy: str = "flee"
    """The evader's behaviour: ``flee`` (scripted), ``random``, ``ddpg`` (a trained, frozen
    DDPG evader: ``evader_model``), or ``external`` (its actions are passed to ``step``, e.g.
    to train an evader)."""
    evader_model: str = "evader-ddpg-paper"
    """With ``evader_policy="ddpg"``: the evader's policy file (``pes train --algo evader-ddpg``
    writes ``policy.pt``), or a shipped one: ``evader-ddpg-paper`` (the default: the snapshot of
    training whose strength matches the paper's evader) or ``evader-ddpg`` (fully trained, far
    stronger)."""

    # --- arena and buildings (§II-A) -------------------------------------------------------
    arena_width: float = 100.0
    """Arena size along x (m); walls stand on its border."""
    arena_height: float = 100.0
    """Arena size along y (m)."""
    layout: str = "grid"
    """``grid`` (generated from the ``grid_*`` / ``block_*`` keys), ``empty`` (no buildings) or
    the path of a layout file (``.yaml`` with a ``buildings`` list, or an ASCII grid ``.txt``)."""
    grid_rows: int = 3
    """Rows of city blocks in the generated grid."""
    grid_cols: int = 3
    """Columns of city blocks in the generated grid."""
    block_size: float = 18.0
    """Side of a city block (m)."""
    street_width: float = 11.5
    """Width of the streets between blocks (m); the grid is centred in the arena."""
    block_jitter: float = 0.0
    """Random shrink of each block side and shift of its centre, up to this many metres."""
    block_removal_prob: float = 0.0
    """Probability that each block (other than those in ``removed_blocks``) is left out."""
    removed_blocks: list[list[int]] = field(default_factory=lambda: [[1, 1]])
    """Blocks left out of the grid as ``[row, col]`` pairs; the default leaves a central square
    (plaza) where the evader starts (see docs/scenario.md, "the default map")."""
    layout_seed: int = 0
    """Seed of the random parts of the layout (jitter, removal, heights)."""
    building_height_range: tuple[float, float] = (25.0, 60.0)
    """Range of building heights (m); used by renderers only (flight is planar)."""

    # --- time -------------------------------------------------------------------------------
    dt: float = 0.1
    """Control step (s): one policy action per step."""
    physics_substeps: int = 10
    """Physics sub-steps per control step (semi-implicit Euler, step ``dt / physics_substeps``)."""
    max_steps: int = 500
    """Episode limit in control steps; reaching it truncates the episode."""

    # --- vehicles (Table III) ------------------------------------------------------------------
    dynamics: Dynamics = "quadrotor"
    """``quadrotor``: eqs. (1)-(2) under a cascaded attitude PID; ``point_mass``: the clipped
    acceleration is applied directly."""
    body_radius: float = 0.3
    """Radius of every vehicle's body (m); touching an obstacle with it is a crash."""
    pursuer_mass: float = 0.8
    """Pursuer mass (kg)."""
    pursuer_max_speed: float = 10.0
    """Pursuer speed limit (m/s)."""
    pursuer_max_accel: float = 5.0
    """Pursuer horizontal acceleration limit (m/s^2); an action of norm 1 asks for it."""
    pursuer_inertia: tuple[float, float, float] = (0.006, 0.006, 0.001)
    """Pursuer moments of inertia Ixx, Iyy, Izz (kg m^2)."""
    evader_mass: float = 1.0
    """Evader mass (kg)."""
    evader_max_speed: float = 12.0
    """Evader speed limit (m/s)."""
    evader_max_accel: float = 4.0
    """Evader horizontal acceleration limit (m/s^2)."""
    evader_inertia: tuple[float, float, float] = (0.006, 0.006, 0.001)
    """Evader moments of inertia Ixx, Iyy, Izz (kg m^2)."""
    attitude_bandwidth: float = 30.0
    """Natural frequency of the closed attitude loop (rad/s); sets the PID gains."""
    attitude_damping: float = 1.0
    """Damping ratio of the closed attitude loop."""
    max_tilt_deg: float = 35.0
    """Largest roll or pitch the outer loop may ask for (degrees)."""
    altitude: float = 10.0
    """Flight altitude of pursuer 0 (m); flight is planar, altitudes matter to renderers only."""
    altitude_step: float = 1.0
    """Altitude difference between consecutive vehicles (m), so that they never collide."""

    # --- start (§II-B) -------------------------------------------------------------------------
    pursuer_spawn_band: float = 5.0
    """Pursuers start at random free spots within this distance of the arena edge (m)."""
    evader_spawn_radius: float = 10.0
    """The evader starts at a random free spot within this distance of the centre (m)."""
    spawn_clearance: float = 1.0
    """Smallest distance from a start position to any building or wall (m)."""

    # --- capture and termination ----------------------------------------------------------------
    capture_count: int = 3
    """Alive pursuers needed within ``capture_radius`` of the evader for a capture."""
    capture_radius: float = 2.0
    """Capture distance (m), centre to centre."""
    capture_hold: int = 5
    """Consecutive steps the capture condition must hold."""

    # --- crashes and damage -------------------------------------------------------------------
    crash_mode: CrashMode = "continue"
    """``continue``: a crashed pursuer is pushed out, stopped and flies on (training);
    ``disable``: it is damaged for good (evaluation)."""
    damaged: int = 0
    """Anti-damage test (§V-D): number of random pursuers disabled during each episode."""
    damage_step: int | Literal["random"] = 0
    """Step at which the ``damaged`` pursuers are disabled: 0 = from the start, or
    ``random`` = a step drawn uniformly from [0, max_steps // 2] each episode."""

    # --- disturbance (§V-B4) ---------------------------------------------------------------------
    disturbance: bool = False
    """Random horizontal force pushes on the vehicles (on in every evaluation of Table IV)."""
    disturbance_prob: float = 0.1
    """Probability, per vehicle and control step, that the disturbance acts during that step."""
    disturbance_scale: float = 0.05
    """Disturbance force as a fraction of the vehicle's weight."""

    # --- rewards (§IV-B, eqs. 8-9) ------------------------------------------------------------
    cooperation_weight: float = 0.1
    """Weight of each alive pursuer's normalised distance in the shared term r_co."""
    self_weight: float = 0.5
    """Weight of the pursuer's own normalised distance in r_self."""
    safe_distance: float = 2.0
    """d_safe (m): obstacles closer than this are penalised by the softplus term."""
    softplus_k: float = 1e-3
    """k of the obstacle term k*log(1 + exp((d_safe - d_obs) / k)) (m)."""
    crash_reward: float = -2.0
    """Reward of a pursuer on a step in which it crashes."""
    capture_reward: float = 5.0
    """Reward of every alive pursuer on the step of capture."""
    encirclement_weight: float = 0.0
    """Not in the paper (0 = its reward): every alive pursuer gets -weight x the length of the
    mean of the unit vectors from the evader to the alive pursuers, each step: 0 when they
    surround the evader evenly, -weight when all come from one side. A training aid against the
    pack that trails the evader (docs/algorithms/cbc_tp.md)."""
    intercept_lead: float = 0.0
    """Not in the paper (0 = its reward): roles for r_self. The alive pursuer nearest the evader
    keeps its distance to the evader; every other one is charged its distance to the point the
    evader reaches in ``intercept_lead`` seconds at its current velocity (s), so that the rest
    of the swarm is paid for cutting the evader off rather than trailing it. A training aid."""
    distance_metric: str = "euclidean"
    """The pursuer-evader distance that eqs. (8)-(9) charge: ``euclidean`` (the paper's) or,
    not in the paper, ``geodesic``, the length of the shortest path round the buildings (through
    waypoints 0.7 m beyond the body radius off their corners; the straight distance where
    nothing stands between). Under the straight distance a pursuer with a building between it
    and the evader is paid for flying into the building; under the path it is paid for going
    round. Capture and ``info["distances"]`` stay straight. A training aid."""
    approach_weight: float = 0.0
    """Not in the paper (0 = its reward): every alive pursuer is charged weight x the speed
    (m/s) at which it flies towards its nearest obstacle beyond the speed from which it could
    still stop before touching it, sqrt(2 x ``approach_decel`` x its gap), each step (weight in
    s/m). It charges flying into a wall rather than being near one, so that a training run may
    lower ``safe_distance`` (and let the pursuers reach an evader waiting at a wall) without
    paying for it in crashes. A training aid."""
    approach_decel: float = 2.5
    """Deceleration (m/s^2) the ``approach_weight`` term allows for stopping: half the pursuers'
    top acceleration by default, a margin for the attitude's lag and the disturbance."""
    evader_capture_reward: float = -5.0
    """Reward of the evader on the step of capture."""
    evader_crash_reward: float = -2.0
    """Reward of the evader on a step in which it touches an obstacle."""

    # --- observations (Table I) ----------------------------------------------------------------
    history_length: int = 10
    """n: steps of history (evader and pursuer positions and velocities) kept for the centralised
    critic and the target predictor."""

    def validate(self) -> EnvConfig:
        """Raise :class:`ConfigError` if any setting is impossible; return ``self``."""
        check_types(self)  # the constructor accepts anything; a typed value is checked here
        positive = [
            "arena_width",
            "arena_height",
            "block_size",
            "dt",
            "body_radius",
            "pursuer_mass",
            "pursuer_max_speed",
            "pursuer_max_accel",
            "evader_mass",
            "evader_max_speed",
            "evader_max_accel",
            "capture_radius",
            "attitude_bandwidth",
            "attitude_damping",
            "softplus_k",
            "approach_decel",
            "max_tilt_deg",
            "pursuer_spawn_band",
            "evader_spawn_radius",
        ]
        for name in positive:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ConfigError(f"{name} must be a positive number, got {value!r}")
        non_negative = [
            "street_width",
            "block_jitter",
            "spawn_clearance",
            "safe_distance",
            "altitude_step",
            "disturbance_scale",
            "cooperation_weight",
            "self_weight",
            "encirclement_weight",
            "intercept_lead",
            "approach_weight",
        ]
        for name in non_negative:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ConfigError(f"{name} must be zero or positive, got {value!r}")
        for name in ["pursuer_inertia", "evader_inertia"]:
            value = getattr(self, name)
            if len(value) != 3 or not all(math.isfinite(v) and v > 0 for v in value):
                raise ConfigError(f"{name} must be three positive numbers, got {list(value)!r}")
        positive_ints = [
            "num_pursuers",
            "grid_rows",
            "grid_cols",
            "physics_substeps",
            "max_steps",
            "capture_count",
            "capture_hold",
            "history_length",
        ]
        for name in positive_ints:
            if getattr(self, name) < 1:
                raise ConfigError(f"{name} must be at least 1, got {getattr(self, name)}")
        # Bounds on what is allocated or looped over per environment: far beyond them a typo
        # would exhaust memory or hang rather than fail.
        limits = {
            "num_pursuers": 256,
            "arena_width": MAX_ARENA,  # the start regions are a grid of 0.5 m cells
            "arena_height": MAX_ARENA,
            "grid_rows": 100,
            "grid_cols": 100,
            "physics_substeps": 1000,
            "history_length": 10_000,
        }
        for name, limit in limits.items():
            if getattr(self, name) > limit:
                raise ConfigError(f"{name} must be at most {limit:g}, got {getattr(self, name)}")
        if self.capture_count > self.num_pursuers:
            raise ConfigError(
                f"capture_count ({self.capture_count}) is above num_pursuers "
                f"({self.num_pursuers}): no capture would be possible"
            )
        if not 0 <= self.damaged <= self.num_pursuers - self.capture_count:
            raise ConfigError(
                f"damaged must be between 0 and num_pursuers - capture_count "
                f"({self.num_pursuers - self.capture_count}), got {self.damaged}"
            )
        if isinstance(self.damage_step, int) and not 0 <= self.damage_step < self.max_steps:
            raise ConfigError(f"damage_step must be in [0, max_steps), got {self.damage_step}")
        if not 0.0 <= self.disturbance_prob <= 1.0:
            raise ConfigError(f"disturbance_prob must be in [0, 1], got {self.disturbance_prob}")
        if not 0.0 <= self.block_removal_prob <= 1.0:
            raise ConfigError(
                f"block_removal_prob must be in [0, 1], got {self.block_removal_prob}"
            )
        if self.max_tilt_deg >= 80:
            raise ConfigError(f"max_tilt_deg must be below 80, got {self.max_tilt_deg}")
        low, high = self.building_height_range
        if not 0 < low <= high:
            raise ConfigError(f"building_height_range must be 0 < low <= high, got {[low, high]}")
        for pair in self.removed_blocks:
            if len(pair) != 2:
                raise ConfigError(f"removed_blocks entries must be [row, col], got {list(pair)!r}")
            row, col = pair
            if self.layout == "grid" and not (
                0 <= row < self.grid_rows and 0 <= col < self.grid_cols
            ):
                raise ConfigError(
                    f"removed_blocks entry {list(pair)!r} lies outside the {self.grid_rows} x "
                    f"{self.grid_cols} grid (rows 0..{self.grid_rows - 1}, cols "
                    f"0..{self.grid_cols - 1})"
                )
        # Every other number must be finite too: NaN passes every comparison above it is not in.
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            values = value if isinstance(value, tuple) else (value,)
            for item in values:
                if isinstance(item, float) and not math.isfinite(item):
                    many = isinstance(value, tuple)
                    what = "hold finite numbers" if many else "be a finite number"
                    raise ConfigError(f"{f.name} must {what}, got {value!r}")
        substep = self.dt / self.physics_substeps
        if substep * self.attitude_bandwidth > 0.5:
            raise ConfigError(
                f"physics sub-step dt/physics_substeps = {substep:g} s is too long for "
                f"attitude_bandwidth {self.attitude_bandwidth:g} rad/s (need product <= 0.5)"
            )
        if self.distance_metric not in ("euclidean", "geodesic"):
            raise ConfigError(
                f"distance_metric must be euclidean or geodesic, got '{self.distance_metric}'"
            )
        if self.evader_policy not in EVADER_POLICIES:
            raise ConfigError(
                f"evader_policy must be one of {', '.join(EVADER_POLICIES)}, "
                f"got '{self.evader_policy}'"
            )
        model = self.evader_model
        shipped_or_file = model in SHIPPED_EVADERS or Path(model).exists()
        if self.evader_policy == "ddpg" and not shipped_or_file:
            raise ConfigError(
                f"evader_model must be {' or '.join(SHIPPED_EVADERS)} or an existing policy "
                f"file, got '{model}'"
            )
        if self.layout not in ("grid", "empty") and not Path(self.layout).is_file():
            raise ConfigError(
                f"layout must be 'grid', 'empty' or an existing layout file, got '{self.layout}'"
            )
        return self

    # --- construction helpers --------------------------------------------------------------
    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> EnvConfig:
        """Build and validate from a mapping; unknown keys and wrong types raise ConfigError."""
        return from_dict(cls, values)

    @classmethod
    def from_yaml(cls, path: str | Path, overrides: list[str] | None = None) -> EnvConfig:
        """Build from a YAML file, then apply ``key=value`` overrides."""
        values = load_yaml(path)
        values.update(dict(parse_override(o) for o in overrides or []))
        return from_dict(cls, values)

    def replace(self, **changes: Any) -> EnvConfig:
        """A checked copy with some fields changed."""
        return from_dict(EnvConfig, changes, base=self)

    def for_evaluation(self, **changes: Any) -> EnvConfig:
        """This scenario under the paper's evaluation protocol (§V-B, Table IV): disturbance
        on, a crash disables the pursuer for good, and the keys of :data:`REWARD_KEYS` back at
        the paper's values, so that every reported reward is the paper's; ``changes`` last."""
        paper = EnvConfig()
        protocol = {"disturbance": True, "crash_mode": "disable"}
        protocol.update({key: getattr(paper, key) for key in REWARD_KEYS})
        return self.replace(**{**protocol, **changes})

    @property
    def arena_diagonal(self) -> float:
        """Arena diagonal (m); rho of eq. (9) is its inverse."""
        return math.hypot(self.arena_width, self.arena_height)

    @property
    def num_vehicles(self) -> int:
        """Pursuers plus the evader."""
        return self.num_pursuers + 1


def resolve_config(config: EnvConfig | dict[str, Any] | None) -> EnvConfig:
    """Accept an ``EnvConfig``, a mapping of overrides, or ``None`` (the defaults)."""
    if config is None:
        return EnvConfig().validate()
    if isinstance(config, EnvConfig):
        # Re-check types too: a dataclass accepts anything at construction.
        return from_dict(EnvConfig, dataclasses.asdict(config))
    if isinstance(config, dict):
        return EnvConfig.from_dict(config)
    raise ConfigError(f"config must be an EnvConfig or a dict, got {type(config).__name__}")

"""Training protocols: how a learner is trained here, apart from what the learner is
(docs/training.md, "Training protocols").

A protocol is a set of opt-in aids, each a small dataclass (or a plain value) of
:class:`Protocol`:

* ``reward``: training reward weights (:class:`pes.EnvConfig` reward keys) used in place of the
  paper's while training; evaluations always use the paper's reward and rules;
* ``disturbance``: train with the random disturbance of §V-B4 on;
* ``noise``: the exploration noise schedule of the deterministic-policy learners
  (:class:`NoiseSchedule`);
* ``n_step``: n-step TD targets of the replay learners;
* ``greedy_envs``: a share of the environments that act without exploration;
* ``demonstrations``: a scripted policy plays the first transitions (:class:`Demonstrations`);
* ``crash_curriculum``: crashes first leave the pursuer flying, and disable it once training
  captures often enough (:class:`CrashCurriculum`);
* ``speed_curriculum``: the evader's top speed rises with the training success
  (:class:`SpeedCurriculum`).

Two named protocols (:data:`PROTOCOLS`): ``paper`` (the paper's reward and rules, no aids) and
``pes`` (the aids that make learning feasible on a CPU budget). A learner applies the aids its
update can use and names the others, with the reason, in :meth:`pes.learn.learner.Learner.aids`;
a run records both in ``config.yaml`` and ``summary.json``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from pes.errors import ConfigError
from pes.strict import check_finite, from_dict, to_dict

REWARD_KEYS = (
    "self_weight",
    "cooperation_weight",
    "safe_distance",
    "crash_reward",
    "capture_reward",
    "approach_weight",
)
"""The :class:`pes.EnvConfig` keys a protocol's training reward may set."""

AIDS = (
    "reward",
    "disturbance",
    "noise",
    "n_step",
    "greedy_envs",
    "demonstrations",
    "crash_curriculum",
    "speed_curriculum",
)
"""The aids of a protocol, in the order the docs list them."""


@dataclass
class NoiseSchedule:
    """Ornstein-Uhlenbeck exploration noise whose scale falls linearly over the first
    ``decay_episodes`` training episodes."""

    theta: float = 0.15
    """Mean reversion rate of the OU process (per step)."""
    sigma: float = 0.2
    """Noise scale at the start of training (action units, actions lie in [-1, 1])."""
    sigma_final: float = 0.2
    """Noise scale reached after ``decay_episodes`` episodes and kept."""
    decay_episodes: int = 2000
    """Episodes (summed over all environments) over which the scale falls."""

    def validate(self) -> None:
        check_finite(self, "noise")
        if self.theta < 0 or self.sigma < 0 or self.sigma_final < 0:
            raise ConfigError("noise: theta, sigma and sigma_final must be non-negative")
        if self.decay_episodes < 1:
            raise ConfigError(f"noise.decay_episodes must be at least 1, got {self.decay_episodes}")

    def scale(self, episodes: int) -> float:
        """The noise scale after ``episodes`` training episodes."""
        frac = min(1.0, episodes / self.decay_episodes)
        return self.sigma + (self.sigma_final - self.sigma) * frac


@dataclass
class Demonstrations:
    """A scripted pursuer policy plays the first ``transitions`` transitions of a run, without
    exploration noise, and its transitions are kept in the replay buffer marked as
    demonstrations (as DDPGfD, Vecerik et al. 2017)."""

    policy: str = "pid-pf"
    """The demonstrator: a scripted pursuer policy (``pid-pf``)."""
    transitions: int = 100_000
    """Transitions the demonstrator plays (one environment step of one environment is one)."""
    bc_weight: float = 0.0
    """Weight of a behaviour-cloning term on the demonstrations in the actor loss (TD3+BC,
    Fujimoto & Gu 2021; 0 = the demonstrations only fill the buffer)."""

    def validate(self) -> None:
        check_finite(self, "demonstrations")
        if self.policy != "pid-pf":
            raise ConfigError(f"demonstrations.policy must be pid-pf, got '{self.policy}'")
        if self.transitions < 0 or self.bc_weight < 0:
            raise ConfigError("demonstrations: transitions and bc_weight must be non-negative")


@dataclass
class CrashCurriculum:
    """Training starts with crashes that leave the pursuer flying (``crash_mode=continue``);
    once a log row's training success rate reaches ``disable_at``, crashes disable the pursuer
    for the rest of the run, as in every evaluation."""

    disable_at: float = 0.3
    """Training success rate (0-1) of a log row from which crashes disable (0: from the first
    episode, the charge on exits kept)."""
    charge_exits: bool = True
    """A pursuer that leaves the game (disabled by a crash, or its episode failed with too few
    pursuers left) is charged its last step's reward, crash term aside, for every step to come
    (discounted), so that with every step's reward negative, leaving does not pay."""

    def validate(self) -> None:
        check_finite(self, "crash_curriculum")
        if not 0.0 <= self.disable_at <= 1.0:
            raise ConfigError(
                f"crash_curriculum.disable_at must be in [0, 1], got {self.disable_at}"
            )


@dataclass
class SpeedCurriculum:
    """The evader starts capped at ``start`` m/s; the cap rises by ``step`` whenever a log row's
    training success rate reaches ``success``, up to ``env.evader_max_speed``."""

    start: float = 6.0
    """Evader speed cap at the start of training (m/s)."""
    step: float = 0.5
    """m/s added at each raise."""
    success: float = 0.3
    """Training success rate (0-1) of a log row that raises the cap."""

    def validate(self) -> None:
        check_finite(self, "speed_curriculum")
        if self.start <= 0 or self.step <= 0:
            raise ConfigError("speed_curriculum: start and step must be positive (m/s)")
        if not 0.0 < self.success <= 1.0:
            raise ConfigError(f"speed_curriculum.success must be in (0, 1], got {self.success}")


@dataclass
class Protocol:
    """A training protocol: its name and its aids (``None`` or 0: the aid is off)."""

    name: str = "paper"
    """``paper``, ``pes``, or ``<name>+custom`` for a named protocol whose aids were changed."""
    reward: dict[str, float] = field(default_factory=dict)
    """Training reward weights (keys of :data:`REWARD_KEYS`); empty = the paper's."""
    disturbance: bool = False
    """Train with the disturbance of §V-B4 on."""
    noise: NoiseSchedule = field(default_factory=NoiseSchedule)
    """Exploration noise schedule of the deterministic-policy learners."""
    n_step: int = 1
    """Transitions summed in a TD target before it bootstraps (1 = the one-step target)."""
    greedy_envs: float = 0.0
    """Share (0-1) of the environments that act without exploration."""
    demonstrations: Demonstrations | None = None
    """Scripted demonstrations at the start of the run (None = none)."""
    crash_curriculum: CrashCurriculum | None = None
    """Crash-rule curriculum (None = crashes follow ``env.crash_mode`` throughout)."""
    speed_curriculum: SpeedCurriculum | None = None
    """Evader-speed curriculum (None = the evader's full speed throughout)."""

    def validate(self) -> None:
        for key, value in self.reward.items():
            if key not in REWARD_KEYS:
                raise ConfigError(
                    f"protocol.reward: '{key}' is not a reward key ({', '.join(REWARD_KEYS)})"
                )
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ConfigError(f"protocol.reward.{key}: expected a number, got {value!r}")
            if not math.isfinite(value):
                raise ConfigError(f"protocol.reward.{key} must be finite, got {value}")
        if self.n_step < 1:
            raise ConfigError(f"protocol.n_step must be at least 1, got {self.n_step}")
        if not 0.0 <= self.greedy_envs <= 1.0:
            raise ConfigError(f"protocol.greedy_envs must be in [0, 1], got {self.greedy_envs}")
        pieces = (self.noise, self.demonstrations, self.crash_curriculum, self.speed_curriculum)
        for piece in pieces:
            if piece is not None:
                piece.validate()

    def active(self) -> list[str]:
        """The aids this protocol turns on (a subset of :data:`AIDS`)."""
        on = {
            "reward": bool(self.reward),
            "disturbance": self.disturbance,
            "noise": self.noise.sigma_final != self.noise.sigma,
            "n_step": self.n_step > 1,
            "greedy_envs": self.greedy_envs > 0,
            "demonstrations": bool(self.demonstrations and self.demonstrations.transitions),
            "crash_curriculum": self.crash_curriculum is not None,
            "speed_curriculum": self.speed_curriculum is not None,
        }
        return [aid for aid in AIDS if on[aid]]

    def env_overrides(self) -> dict[str, Any]:
        """The scenario keys this protocol sets for the training environments."""
        out: dict[str, Any] = dict(self.reward)
        if self.disturbance:
            out["disturbance"] = True
        if self.crash_curriculum is not None:
            out["crash_mode"] = "continue"
        return out


PAPER = Protocol(name="paper")
"""The paper's protocol: its reward and rules, constant OU noise of scale 0.2, one-step TD
targets, no demonstrations or curricula."""

PES = Protocol(
    name="pes",
    # the distance terms of eqs. (8)-(9) ten times heavier, a larger capture reward and crash
    # penalty, a smaller safety distance and a reward for approaching the evader no faster than
    # the pursuer can stop (docs/algorithms/cbc_tp.md, "Training protocol")
    reward=dict(
        self_weight=5.0,
        cooperation_weight=1.0,
        capture_reward=25.0,
        crash_reward=-10.0,
        safe_distance=1.5,
        approach_weight=0.3,
    ),
    disturbance=True,
    noise=NoiseSchedule(sigma=0.2, sigma_final=0.05, decay_episodes=1800),
    n_step=3,
    greedy_envs=0.5,
    demonstrations=Demonstrations(policy="pid-pf", transitions=100_000, bc_weight=0.0),
    crash_curriculum=CrashCurriculum(disable_at=0.3, charge_exits=True),
)
"""The aids that make learning feasible on a CPU budget (docs/algorithms/cbc_tp.md): the
shaped training reward, disturbance, noise falling from 0.2 to 0.05 over 1800 episodes,
three-step TD targets, half the environments greedy, 100,000 transitions of PID(PF)
demonstrations, and crashes that disable once training captures 30 %."""

PROTOCOLS = {"paper": PAPER, "pes": PES}
"""Protocol name -> protocol."""


def build_protocol(name: str, overrides: dict[str, Any] | None = None) -> Protocol:
    """The protocol ``name`` with ``overrides`` (a mapping of :class:`Protocol` keys; a piece
    given as a mapping is merged key by key into the protocol's, ``null`` turns it off)."""
    if name not in PROTOCOLS:
        raise ConfigError(f"protocol must be one of {', '.join(PROTOCOLS)}, got '{name}'")
    base = to_dict(PROTOCOLS[name])
    merged = merge(base, overrides or {})
    merged.pop("name", None)
    protocol = protocol_from_dict(merged)
    # a protocol whose aids were changed is not the named one any more
    protocol.name = name if dict(to_dict(protocol), name=name) == base else f"{name}+custom"
    return protocol


def merge(base: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """``base`` with ``overrides`` merged in, mapping into mapping (a non-mapping replaces)."""
    out = dict(base)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merge(out[key], value)
        else:
            out[key] = value
    return out


PIECES = {
    "noise": NoiseSchedule,
    "demonstrations": Demonstrations,
    "crash_curriculum": CrashCurriculum,
    "speed_curriculum": SpeedCurriculum,
}


def protocol_from_dict(values: dict[str, Any]) -> Protocol:
    """A :class:`Protocol` from plain values (as in ``config.yaml``), each piece checked."""
    if not isinstance(values, dict):
        raise ConfigError(f"protocol must be a mapping of aids to settings, got {values!r}")
    values = dict(values)
    for key, cls in PIECES.items():
        piece = values.get(key)
        if piece is None:
            if key == "noise" and key in values:
                raise ConfigError("protocol.noise cannot be null (set sigma to 0 for none)")
            continue
        if isinstance(piece, bool) and key != "noise":
            values[key] = cls() if piece else None
            continue
        if not isinstance(piece, dict):
            raise ConfigError(f"protocol.{key}: expected a mapping or null, got {piece!r}")
        values[key] = from_dict(cls, piece, label=f"protocol.{key}")
    protocol = Protocol(**{k: v for k, v in values.items() if k in PIECES})
    rest = {k: v for k, v in values.items() if k not in PIECES}
    return from_dict(Protocol, rest, base=protocol, label="protocol")

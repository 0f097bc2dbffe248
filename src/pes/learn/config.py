"""The configuration of a training run: the run's own settings (:class:`TrainConfig`), the
learner's (a :class:`LearnerConfig` subclass that each method defines with only the keys it
reads) and the training protocol (:class:`pes.learn.protocol.Protocol`).

A run's configuration is built in layers (:func:`build_train_config`): the dataclass defaults,
then the method's preset for the budget (``paper``, ``quick``, ``tiny``), then the protocol,
then a YAML file (``--config``), then ``--set key=value`` overrides. In ``config.yaml`` and in
overrides the learner's keys sit under ``learner``, the protocol's under ``protocol`` and the
scenario's under ``env``; a bare key (``--set lr_actor=1e-4``) is looked up among the run's
keys, then the learner's, then the protocol's.
"""

from __future__ import annotations

import dataclasses
import difflib
from dataclasses import dataclass, field
from typing import Any, ClassVar

from pes.errors import ConfigError
from pes.learn.protocol import PROTOCOLS, Protocol, build_protocol, merge, protocol_from_dict
from pes.sim.config import EnvConfig
from pes.strict import check_finite, from_dict, to_dict


@dataclass
class LearnerConfig:
    """Base of every method's configuration: a dataclass of the keys its learner reads.

    Subclasses list their strictly positive and non-negative keys in ``POSITIVE`` and
    ``NON_NEGATIVE``; :meth:`validate` checks those, every float for NaN and infinity, and
    calls :meth:`check` for the rest."""

    POSITIVE: ClassVar[tuple[str, ...]] = ()
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = ()

    def validate(self) -> None:
        label = getattr(self, "method", type(self).__name__)
        check_finite(self, label)
        for name in self.POSITIVE:
            if getattr(self, name) <= 0:
                raise ConfigError(f"{label}: {name} must be positive, got {getattr(self, name)}")
        for name in self.NON_NEGATIVE:
            if getattr(self, name) < 0:
                raise ConfigError(
                    f"{label}: {name} must be non-negative, got {getattr(self, name)}"
                )
        if hasattr(self, "gamma") and not 0.0 <= self.gamma < 1.0:
            raise ConfigError(f"{label}: gamma must be in [0, 1), got {self.gamma}")
        if hasattr(self, "tau") and not 0.0 < self.tau <= 1.0:
            raise ConfigError(f"{label}: tau must be in (0, 1], got {self.tau}")
        if hasattr(self, "buffer_size") and self.batch_size > self.buffer_size:
            raise ConfigError(
                f"{label}: batch_size ({self.batch_size}) exceeds buffer_size ({self.buffer_size})"
            )
        self.check()

    def check(self) -> None:
        """Method-specific checks beyond :meth:`validate`'s (none by default)."""


@dataclass
class OffPolicyConfig(LearnerConfig):
    """The settings every replay learner reads (the paper's, §V-A, by default)."""

    gamma: float = 0.95
    """Discount factor."""
    lr_actor: float = 1e-3
    """Adam learning rate of the actor."""
    lr_critic: float = 1e-3
    """Adam learning rate of the critic."""
    tau: float = 1e-2
    """Soft target update rate."""
    buffer_size: int = 1_000_000
    """Transitions kept in the replay buffer."""
    batch_size: int = 512
    """Minibatch of the updates (M)."""
    update_every: int = 50
    """Collected transitions per gradient update (the paper updates every 50)."""
    warmup: int = 5000
    """Transitions collected before the first update."""
    grad_clip: float = 1.0
    """Gradient norm clip (0 = none)."""

    POSITIVE: ClassVar[tuple[str, ...]] = (
        "lr_actor",
        "lr_critic",
        "buffer_size",
        "batch_size",
        "update_every",
    )
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = ("warmup", "grad_clip")


@dataclass
class TrainConfig:
    """A training run. Times are in minutes."""

    algo: str = "cbc-tp"
    """Method (see ``pes train --help``)."""
    preset: str = "quick"
    """Budget preset applied under the user's settings: ``paper`` (the paper's settings),
    ``quick`` (2,000,000 env steps: 10 to 90 minutes of one CPU thread, by method), ``gpu``
    (the quick settings at a GPU's sizes, 20,000,000 env steps) or ``tiny`` (tests)."""
    protocol: Protocol = field(default_factory=Protocol)
    """The training protocol (:mod:`pes.learn.protocol`): ``paper`` or ``pes`` and its aids."""
    learner: Any = None
    """The method's settings (its :class:`LearnerConfig`)."""
    env: dict[str, Any] = field(default_factory=dict)
    """Scenario settings (:class:`pes.EnvConfig` keys) of the training environments, before the
    protocol's training reward and rules."""
    seed: int = 0
    """Seed of the environments, the network initialisation, the noise and the sampling."""
    device: str = "cpu"
    """``cpu`` or ``cuda``."""
    threads: int = 0
    """Torch CPU threads (0 = torch's default)."""
    compile_env: bool = True
    """Fuse the simulator step with ``torch.compile`` (eager fallback if it fails)."""
    episodes: int = 4000
    """Training episodes (finished episodes, summed over all environments)."""
    time_limit: float = 0.0
    """Stop after this many minutes of training (0 = no limit); a checkpoint is written."""
    cpu_limit: float = 0.0
    """Stop after this many minutes of this process's CPU time (all its threads; 0 = no
    limit): unlike ``time_limit``, the same work whatever else shares the machine's cores,
    though not on another CPU (docs/training.md)."""
    cpu_scale: float = 1.0
    """The CPU time this CPU takes for the work of one CPU minute of the CPU that
    ``cpu_limit`` is counted on (``benchmarks/host_speed.py`` measures it): the run stops when
    its CPU time reaches ``cpu_limit * cpu_scale`` minutes, so that a run on a slower CPU does
    the work of a ``cpu_limit`` run on the reference CPU."""
    env_steps: int = 0
    """Stop after this many environment steps (one control step of one environment; 0 = no
    limit): a budget of experience that is the same on every machine, unlike the time limits
    (a checkpoint is written)."""
    num_envs: int = 1
    """Environments collected from at once."""
    init_from: str = ""
    """Start every network from this run's ``checkpoint.pt`` (same method and architecture);
    optimisers, replay buffer, noise and counters start fresh. A policy file or a shipped
    model's name (``cbc-tp``) gives only the acting networks (and their target copies)."""
    log_every: int = 100
    """Episodes per log row (success rate every 100 episodes, as Fig. 6)."""
    checkpoint_every: float = 5.0
    """Minutes between checkpoints (one is also written at the end)."""
    checkpoint_buffer: bool = True
    """Save the replay buffer's contents in checkpoints (exact resumption)."""
    snapshots: bool = False
    """Also keep the policy of every log row as ``snapshots/ep<episodes>.pt``."""
    eval_episodes: int = 100
    """Episodes of the evaluation at the end of training (0 = none)."""
    tensorboard: bool = True
    """Also write TensorBoard logs (needs the ``tensorboard`` package)."""

    def validate(self) -> None:
        check_finite(self, "train")
        for name in ("episodes", "num_envs", "log_every"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{name} must be at least 1, got {getattr(self, name)}")
        limits = ("time_limit", "cpu_limit", "env_steps")
        for name in (*limits, "checkpoint_every", "eval_episodes", "threads"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{name} must be non-negative, got {getattr(self, name)}")
        if self.cpu_scale <= 0:
            raise ConfigError(f"cpu_scale must be positive, got {self.cpu_scale}")
        if self.device not in ("cpu", "cuda"):
            raise ConfigError(f"device must be cpu or cuda, got '{self.device}'")
        env = self.env_config()
        curriculum = self.protocol.speed_curriculum
        if curriculum is not None and curriculum.start > env.evader_max_speed:
            raise ConfigError(
                f"protocol.speed_curriculum.start ({curriculum.start:g} m/s) exceeds "
                f"env.evader_max_speed ({env.evader_max_speed:g})"
            )
        if self.protocol.crash_curriculum is not None and env.crash_mode != "continue":
            raise ConfigError("protocol.crash_curriculum needs env.crash_mode=continue")

    def env_config(self) -> EnvConfig:
        """The training scenario: ``env`` with the protocol's training reward and rules (keys
        set in ``env`` win)."""
        return EnvConfig.from_dict({**self.protocol.env_overrides(), **self.env})

    def to_dict(self) -> dict[str, Any]:
        return to_dict(self)


RUN_KEYS = tuple(
    f.name for f in dataclasses.fields(TrainConfig) if f.name not in ("protocol", "learner")
)
"""The keys of :class:`TrainConfig` besides its ``protocol`` and ``learner`` sections."""


def build_train_config(
    algo: str,
    learner_config: type[LearnerConfig],
    presets: dict[str, dict[str, Any]],
    preset: str = "quick",
    protocol: str | None = None,
    values: dict[str, Any] | None = None,
) -> TrainConfig:
    """The configuration of method ``algo`` (whose settings are ``learner_config``) under its
    preset ``preset`` (a key of ``presets``) and training protocol ``protocol`` (default:
    ``paper`` for the paper preset, ``pes`` otherwise), with ``values`` (as in ``config.yaml``,
    or bare keys) on top.

    A preset holds run keys, learner keys, an ``env`` mapping and optionally a ``protocol``
    mapping that scales the protocol's aids to its budget (the tiny preset's shorter
    demonstrations); ``values`` may hold ``env``, ``learner`` and ``protocol`` mappings, merged key
    by key into the preset's, and a ``protocol`` name.
    """
    if preset not in presets:
        raise ConfigError(f"preset must be one of {', '.join(presets)}, got '{preset}'")
    values = dict(values or {})
    name = values.pop("protocol", None) if isinstance(values.get("protocol"), str) else None
    name = protocol or name or ("paper" if preset == "paper" else "pes")
    learner_keys = [f.name for f in dataclasses.fields(learner_config)]
    preset_values = dict(presets[preset])
    # a preset scales the aids the protocol has; it turns none on, but may give the exploration
    # noise (always there) a schedule of its own, as the DDPG evader's
    scaling = preset_values.pop("protocol", {})
    active = PROTOCOLS[name].active() if name in PROTOCOLS else []
    if {"sigma", "sigma_final"} & set(scaling.get("noise", {})):
        active = [*active, "noise"]
    preset_values["protocol"] = {k: v for k, v in scaling.items() if k in active}
    layers = [
        split_values(preset_values, learner_keys, algo),
        split_values(values, learner_keys, algo),
    ]
    merged: dict[str, Any] = {"env": {}, "learner": {}, "protocol": {}}
    for layer in layers:
        merged = merge(merged, layer)
    run = {k: v for k, v in merged.items() if k not in ("env", "learner", "protocol")}
    run.update(algo=algo, preset=preset)
    cfg = from_dict(TrainConfig, {**run, "env": merged["env"]}, label="training")
    cfg.learner = from_dict(learner_config, merged["learner"], label=f"{algo} learner")
    cfg.protocol = build_protocol(name, merged["protocol"])
    cfg.validate()
    return cfg


def split_values(values: dict[str, Any], learner_keys: list[str], algo: str) -> dict[str, Any]:
    """``values`` sorted into run keys and the ``env``, ``learner`` and ``protocol`` sections:
    bare keys go to the run, the learner or the protocol (in that order), and ``section.key``
    names a section's key (``protocol.demonstrations.transitions``)."""
    out: dict[str, Any] = {"env": {}, "learner": {}, "protocol": {}}
    protocol_keys = [f.name for f in dataclasses.fields(Protocol) if f.name != "name"]
    for key, value in values.items():
        if key in ("env", "learner", "protocol"):
            if not isinstance(value, dict):
                raise ConfigError(f"{key} must be a mapping of keys to values, got {value!r}")
            out[key] = merge(out[key], value)
            continue
        head, _, rest = key.partition(".")
        if rest and head in ("env", "learner", "protocol"):
            out[head] = merge(out[head], nest(rest, value))
        elif key in RUN_KEYS:
            out[key] = value
        elif key in learner_keys:
            out["learner"][key] = value
        elif key in protocol_keys:
            out["protocol"][key] = value
        else:
            known = [*RUN_KEYS, *learner_keys, *protocol_keys]
            close = difflib.get_close_matches(key, known, n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise ConfigError(f"unknown key '{key}' for {algo}{hint}")
    return out


def nest(dotted: str, value: Any) -> dict[str, Any]:
    """``"a.b", v`` -> ``{"a": {"b": v}}``."""
    head, _, rest = dotted.partition(".")
    return {head: nest(rest, value) if rest else value}


def train_config_from_dict(
    values: dict[str, Any], learner_config: type[LearnerConfig]
) -> TrainConfig:
    """A recorded configuration (``config.yaml``, a checkpoint's ``train_config``) read back
    exactly as it was written."""
    values = dict(values)
    learner = values.pop("learner", None) or {}
    protocol = values.pop("protocol", None) or {}
    cfg = from_dict(TrainConfig, values, label="training")
    cfg.learner = from_dict(learner_config, learner, label=f"{cfg.algo} learner")
    name = protocol.get("name", "paper") if isinstance(protocol, dict) else "paper"
    cfg.protocol = protocol_from_dict({k: v for k, v in protocol.items() if k != "name"})
    cfg.protocol.name = name
    cfg.validate()
    return cfg

"""The interface between the training loop (:func:`pes.learn.trainer.train`) and a method.

A method is one file under ``pes/algos/``: a :class:`LearnerConfig` subclass with the keys its
learner reads, its presets, and a :class:`Learner` subclass; one line of
``pes.algos.ALGOS`` registers it (docs/algorithms/write_your_own.md).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

import torch
from torch import Tensor, nn

from pes.learn.config import LearnerConfig, TrainConfig
from pes.learn.protocol import Protocol
from pes.sim.config import EnvConfig

ENV_AIDS = ("reward", "disturbance", "crash_curriculum", "speed_curriculum")
"""Aids the training loop applies to the environments, the same for every learner."""


class Learner(ABC):
    """A learner as the training loop drives it.

    Per vector step the loop calls :meth:`act`, steps the environments, then :meth:`record`;
    :meth:`episode_reset` for the environments that finished; :meth:`update` as many times as
    :meth:`update_credit` allows once :meth:`ready`. Checkpoints hold :meth:`modules`,
    :meth:`optimizers` and :meth:`state_dict`; policy files hold :meth:`policy_modules`, which
    :meth:`build_policy` rebuilds.
    """

    name: ClassVar[str]
    """The ``--algo`` name."""
    Config: ClassVar[type[LearnerConfig]]
    """The method's settings."""
    PRESETS: ClassVar[dict[str, dict[str, Any]]]
    """Budget presets (``paper``, ``quick``, ``tiny``): run keys, learner keys and ``env``."""
    pursuer: ClassVar[bool] = True
    """Whether the trained policy controls the pursuers (False: the evader)."""
    default_protocol: ClassVar[str] = "pes"
    """The protocol of the ``quick`` and ``tiny`` presets when none is named (the ``paper``
    preset's is ``paper``)."""
    on_policy: ClassVar[bool] = False
    """On-policy learners are :meth:`ready` once per full rollout, and update once then."""
    AIDS: ClassVar[dict[str, str]] = {}
    """How the learner applies each learner-level aid of a protocol (``noise``, ``n_step``,
    ``greedy_envs``, ``demonstrations``, ``crash_curriculum.charge_exits``): aid -> ``""``
    when applied as the protocol describes it, or the reason it is not (or how it is adapted).
    An aid missing here is not applied."""

    TUNE_SPACE: ClassVar[dict[str, tuple]] = {}
    """The keys ``pes tune`` searches (two to four): key -> ``("log", low, high)`` or
    ``("choice", [values])`` (:mod:`pes.experiments.tune`)."""

    def __init__(self, cfg: TrainConfig, env_cfg: EnvConfig, device: torch.device) -> None:
        self.cfg = cfg
        self.env_cfg = env_cfg
        self.device = device
        self.updates = 0

    # --- what the protocol does with this learner ------------------------------------------------
    @classmethod
    def aids(cls, protocol: Protocol) -> dict[str, str]:
        """Each aid ``protocol`` turns on -> ``"applied"`` or why it is not applied as such."""
        out: dict[str, str] = {}
        active = protocol.active()
        if protocol.crash_curriculum is not None and protocol.crash_curriculum.charge_exits:
            active.append("charge_exits")
        for aid in active:
            if aid in ENV_AIDS:
                out[aid] = "applied"
            elif aid in cls.AIDS:
                out[aid] = cls.AIDS[aid] or "applied"
            else:
                out[aid] = f"not applied: {cls.name} has no use for it"
        return out

    @classmethod
    def applies(cls, aid: str) -> bool:
        """Whether this learner applies ``aid`` as the protocol describes it."""
        return cls.AIDS.get(aid) == ""

    @staticmethod
    def adapt_env(env_cfg: EnvConfig) -> EnvConfig:
        """The training scenario (unchanged: the configured evader plays)."""
        return env_cfg

    # --- acting ----------------------------------------------------------------------------------
    @abstractmethod
    def act(
        self, obs: Tensor, info: dict[str, Tensor], noise_scale: float, gen: torch.Generator
    ) -> tuple[Tensor, Tensor | None]:
        """Actions for one vector step: the pursuers' (E, N, 2) in [-1, 1] and the evader's
        (E, 2) or None (the environment's evader plays). ``noise_scale`` is the protocol's
        exploration scale now."""

    @abstractmethod
    def record(
        self,
        before: dict[str, Tensor],
        actions: Tensor,
        evader_actions: Tensor | None,
        reward: Tensor,
        terminated: Tensor,
        after: dict[str, Tensor],
    ) -> None:
        """Store one vector step: ``before``/``after`` are the infos around ``env.step``,
        ``reward`` (E, N), ``terminated`` (E,)."""

    def episode_reset(self, done: Tensor) -> None:  # noqa: B027 - a hook, nothing by default
        """The environments ``done`` (E,) bool start new episodes."""

    def demonstrating(self) -> bool:
        """Whether a demonstrator, not the learner, plays the next step."""
        return False

    def on_restart(self) -> None:  # noqa: B027 - a hook, nothing by default
        """The environments restart (every episode abandoned): drop what spans them."""

    # --- learning --------------------------------------------------------------------------------
    @abstractmethod
    def ready(self) -> bool:
        """Whether :meth:`update` may run."""

    def update_credit(self) -> float:
        """Updates earned by one vector step once :meth:`ready` (on-policy: one per rollout)."""
        return 1.0

    @abstractmethod
    def update(self, gen: torch.Generator) -> dict[str, float]:
        """One update; returns its metrics (log columns)."""

    @staticmethod
    def score(success_rate: float, episode_steps: float) -> float:
        """Training score of a log row (higher is better): success, then speed."""
        return success_rate - 1e-5 * episode_steps

    # --- saving ----------------------------------------------------------------------------------
    @abstractmethod
    def modules(self) -> dict[str, nn.Module]:
        """Every network, by name (checkpoints)."""

    @abstractmethod
    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        """Every optimiser, by name (checkpoints)."""

    @abstractmethod
    def policy_modules(self) -> dict[str, nn.Module]:
        """What a deployed policy needs (policy files hold only these)."""

    def state_dict(self) -> dict[str, Any]:
        """What a checkpoint holds besides networks and optimisers (buffer contents and noise
        state are saved by the loop)."""
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:  # noqa: B027 - a hook, nothing by default
        """Restore :meth:`state_dict`."""

    @classmethod
    @abstractmethod
    def build_policy(
        cls, cfg: TrainConfig, env_cfg: EnvConfig, device: torch.device | str
    ) -> tuple[nn.Module, dict[str, nn.Module]]:
        """An untrained policy of this architecture for ``env_cfg``, and its modules by name
        (what a policy file's ``policy`` loads into)."""

    @staticmethod
    def fixed_swarm(cfg: TrainConfig) -> str | None:
        """Why a trained policy only serves the swarm size it was trained on (None: any)."""
        return None

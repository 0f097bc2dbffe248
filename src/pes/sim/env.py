"""The batched pursuit-evasion environment: ``make_env`` and ``PursuitEvasionEnv``
(docs/interfaces.md)."""

from __future__ import annotations

import secrets
import warnings
from typing import Any

import torch
from torch import Tensor

from pes.errors import ActionError, ConfigError, PESError
from pes.sim import kernels, rng, scenario
from pes.sim.config import EnvConfig, resolve_config
from pes.sim.layout import Layout

ACTION_LIMIT = 1e6
"""Largest magnitude of an action component that ``step`` accepts. Actions are fractions of the
maximum acceleration, clipped to norm 1; far beyond that the clipping overflows float32."""


class PursuitEvasionEnv:
    """``num_envs`` pursuit-evasion games stepped together as tensors on one device.

    ``reset(seed=None) -> (obs, info)`` and ``step(actions) -> (obs, reward, terminated,
    truncated, info)`` with

    * ``obs``: (num_envs, N, N, 8) float32, pursuer i's rows as Table I (see
      :func:`pes.sim.scenario.observe`); masked rows are zero, ``info["obs_mask"]`` says which;
    * ``actions``: (num_envs, N, 2) desired horizontal accelerations as fractions of the pursuer
      max acceleration (clipped to norm 1); dead pursuers' actions are ignored;
    * ``reward``: (num_envs, N) eqs. (8)-(9) plus crash and capture rewards; 0 for dead pursuers;
    * ``terminated``/``truncated``: (num_envs,) bool. Finished environments reset themselves:
      the returned ``obs`` is then the first of the next episode, and ``info["final_obs"]`` the
      last of the finished one.

    ``info`` describes the step just taken -- ``success`` (E,), ``steps`` (E,) episode length so
    far, ``crashes`` (E,) pursuer crashes this episode, ``crashed`` (E, N) crashes this step,
    ``alive`` (E, N), ``distances`` (E, N) pursuer-evader distances (m), ``positions`` and
    ``velocities`` (E, N+1, 2) in m and m/s (pursuers, then the evader), ``evader_reward`` (E,),
    ``evader_contact`` (E,) -- and what the policy sees next: ``obs_mask`` (E, N, N),
    ``state`` (E, N+1, 8) the global state, ``history`` (E, n, N+1, 4) the last n frames of
    normalised [position, velocity], ``evader_obs`` (E, N+1, 8); the same before auto-reset
    under ``final_obs``, ``final_obs_mask``, ``final_state``, ``final_history``,
    ``final_evader_obs``.

    The same seed gives the same trajectories, and environment ``i`` of a batch reset with seed
    ``s`` behaves exactly as a single environment reset with seed ``s + i``.
    """

    def __init__(
        self,
        config: EnvConfig | dict[str, Any] | None = None,
        num_envs: int = 1,
        device: str | torch.device = "cpu",
        seed: int | None = None,
        *,
        compile: bool = False,
        check_actions: bool = True,
        wait_kernels: bool = False,
    ) -> None:
        self.config = resolve_config(config)
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ConfigError(f"num_envs must be a positive integer, got {num_envs!r}")
        self.num_envs = num_envs
        self.device = resolve_device(device)
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
            raise ConfigError(f"seed must be an integer, got {seed!r}")
        self._seed = seed if seed is not None else secrets.randbits(31)
        self.check_actions = check_actions
        if wait_kernels and self.device.type == "cpu":  # compile=True: its eager reset uses them
            kernels.wait()
        self.scenario = scenario.build_scenario(self.config, self.device)
        sc = self.scenario
        # Auto-reset handles up to this many finished environments per pass (static shapes).
        self.reset_capacity = min(num_envs, max(8, num_envs // 32))

        def step_fn(state: dict[str, Tensor], actions: Tensor, evader_action: Tensor | None):
            return scenario.step_core(sc, state, actions, evader_action)

        def reset_fn(state: dict[str, Tensor], views: dict[str, Tensor], pending: Tensor):
            return scenario.reset_pass(sc, state, views, pending, self.reset_capacity)

        self._step_fn = _Fused(step_fn) if compile else step_fn
        self._reset_fn = _Fused(reset_fn) if compile else reset_fn
        self.state: dict[str, Tensor] | None = None

    # --- facts about the environment ----------------------------------------------------------
    @property
    def num_pursuers(self) -> int:
        return self.config.num_pursuers

    @property
    def agents(self) -> list[str]:
        """Pursuer names, ``pursuer_0`` ... ``pursuer_{N-1}``."""
        return [f"pursuer_{i}" for i in range(self.num_pursuers)]

    @property
    def layout(self) -> Layout:
        return self.scenario.layout

    @property
    def obs_shape(self) -> tuple[int, int, int]:
        """Shape of one environment's observation: (N, N, 8)."""
        n = self.num_pursuers
        return (n, n, scenario.OBS_FEATURES)

    @property
    def action_shape(self) -> tuple[int, int]:
        """Shape of one environment's actions: (N, 2)."""
        return (self.num_pursuers, 2)

    def set_evader_max_speed(self, speed: float) -> None:
        """Cap the evader's speed at ``speed`` m/s from the next step on (a training curriculum).

        Only the cap of the dynamics changes: the evader's observations keep the configured
        ``evader_max_speed`` as their velocity unit, so a learned evader sees the units it was
        trained in. Works on the fused step too (the cap is a tensor the graph reads).
        """
        if not 0.0 < speed <= self.config.evader_max_speed:
            raise ConfigError(
                f"evader speed must be in (0, {self.config.evader_max_speed:g}] m/s, got {speed}"
            )
        self.scenario.params.max_speed[-1] = float(speed)

    @property
    def evader_max_speed(self) -> float:
        """The evader's current speed cap, m/s."""
        return float(self.scenario.params.max_speed[-1])

    # --- the API --------------------------------------------------------------------------------

    @property
    def compiled(self) -> bool:
        """Whether the step and the reset pass run fused by ``torch.compile`` (False when it was
        not asked for, or when compilation failed here and the env fell back to eager)."""
        fns = (self._step_fn, self._reset_fn)
        return all(isinstance(f, _Fused) and not f.failed for f in fns)

    def reset(self, seed: int | None = None) -> tuple[Tensor, dict[str, Tensor]]:
        """Start a new episode in every environment.

        With ``seed``, environment ``i`` is re-keyed by ``seed + i``; without it, each
        environment moves on to its next episode.
        """
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, int):
                raise ConfigError(f"seed must be an integer, got {seed!r}")
            self._seed = seed
        if seed is not None or self.state is None:
            key = rng.env_keys(self._seed, self.num_envs, self.device)
            episode = torch.zeros(self.num_envs, dtype=torch.int64, device=self.device)
        else:
            counters = scenario.Counters(*self.state["counters"].unbind(0))
            key, episode = counters.key, counters.episode + 1
        state = scenario.spawn(self.scenario, key, episode)
        v, _, f = scenario.unpack(state)
        views = scenario.observe(self.scenario, v, f)
        self.state = state
        info = {
            "obs_mask": views["obs_mask"],
            "state": views["state"],
            "evader_obs": views["evader_obs"],
            "history": state["history"],
            "alive": f.alive,
        }
        return views["obs"], info

    def step(self, actions: Tensor, evader_actions: Tensor | None = None):
        """Advance every environment by one control step of ``config.dt`` seconds.

        Args:
            actions: (num_envs, N, 2) pursuer actions.
            evader_actions: (num_envs, 2), only with ``evader_policy="external"``.

        Returns:
            ``(obs, reward, terminated, truncated, info)`` as described in the class docstring.
        """
        if self.state is None:
            raise PESError("call reset() before step()")
        actions = self._check_actions(actions, (self.num_envs, self.num_pursuers, 2), "actions")
        if self.config.evader_policy == "external":
            if evader_actions is None:
                raise ActionError("evader_policy is 'external': pass evader_actions to step()")
            evader_actions = self._check_actions(
                evader_actions, (self.num_envs, 2), "evader_actions"
            )
        elif evader_actions is not None:
            raise ActionError(
                f"evader_policy is '{self.config.evader_policy}': set evader_policy='external' "
                "to pass evader_actions"
            )
        stepped, out = self._step_fn(self.state, actions, evader_actions)
        done = out["terminated"] | out["truncated"]
        views = {k: out[k] for k in scenario.VIEW_KEYS}
        final_history = stepped["history"]
        if bool(done.any()):
            # Finished environments start their next episode: their rows of the stepped state
            # and of copies of the observations are overwritten in place, in passes of up to
            # reset_capacity environments (one pass in the common case).
            views = {k: v.clone() for k, v in views.items()}
            final_history = final_history.clone()
            pending = done
            while bool(pending.any()):
                pending = self._reset_fn(stepped, views, pending)
        self.state = stepped
        info = {
            "success": out["success"],
            "steps": out["steps"],
            "crashes": out["crashes"],
            "crashed": out["crashed"],
            "alive": out["alive"],
            "distances": out["distances"],
            "positions": out["positions"],
            "velocities": out["velocities"],
            "evader_reward": out["evader_reward"],
            "evader_contact": out["evader_contact"],
            "obs_mask": views["obs_mask"],
            "state": views["state"],
            "history": self.state["history"],
            "evader_obs": views["evader_obs"],
            "final_obs": out["obs"],
            "final_obs_mask": out["obs_mask"],
            "final_state": out["state"],
            "final_history": final_history,
            "final_evader_obs": out["evader_obs"],
        }
        return views["obs"], out["reward"], out["terminated"], out["truncated"], info

    def _check_actions(self, actions: Any, shape: tuple[int, ...], name: str) -> Tensor:
        if not isinstance(actions, Tensor):
            try:
                actions = torch.as_tensor(actions, dtype=torch.float32)
            except (TypeError, ValueError, RuntimeError):
                raise ActionError(f"{name} must be a tensor of shape {list(shape)}") from None
        if tuple(actions.shape) != shape:
            raise ActionError(f"{name} must have shape {list(shape)}, got {list(actions.shape)}")
        if not actions.is_floating_point():
            raise ActionError(f"{name} must be floating point, got {actions.dtype}")
        # Checked in float32, as used (in float16 the limit itself would be infinite).
        actions = actions.to(device=self.device, dtype=torch.float32)
        # One reduction in the common case: NaN fails the comparison too.
        if self.check_actions and not bool((actions.abs() <= ACTION_LIMIT).all()):
            if not bool(torch.isfinite(actions).all()):
                raise ActionError(f"{name} hold NaN or infinite values")
            # Far beyond norm 1 the clipping itself overflows float32 (and turns to NaN).
            raise ActionError(
                f"{name} hold values beyond {ACTION_LIMIT:g}: actions are fractions of the "
                "maximum acceleration, in [-1, 1] (clipped to norm 1)"
            )
        return actions

    # --- state access, for recorders and tests -------------------------------------------------
    @property
    def positions(self) -> Tensor:
        """(num_envs, N + 1, 2) positions in metres, pursuers then evader."""
        v = self._vehicles()
        return torch.stack([v.x, v.y], dim=-1)

    @property
    def velocities(self) -> Tensor:
        """(num_envs, N + 1, 2) velocities in m/s, pursuers then evader."""
        v = self._vehicles()
        return torch.stack([v.vx, v.vy], dim=-1)

    @property
    def alive(self) -> Tensor:
        """(num_envs, N) bool: pursuers neither damaged nor disabled by a crash."""
        if self.state is None:
            raise PESError("call reset() first")
        return self.state["flags"][0]

    def _vehicles(self) -> scenario.Vehicles:
        if self.state is None:
            raise PESError("call reset() first")
        return scenario.Vehicles(*self.state["vehicles"].unbind(0))

    def get_state(self) -> dict[str, Tensor]:
        """A copy of the simulator state (see :mod:`pes.sim.scenario`)."""
        if self.state is None:
            raise PESError("call reset() before get_state()")
        return {k: v.clone() for k, v in self.state.items()}

    def set_state(self, state: dict[str, Tensor]) -> None:
        """Replace the simulator state (shapes must match this environment's)."""
        if self.state is not None:
            for k, v in self.state.items():
                if k not in state or state[k].shape != v.shape:
                    raise PESError(f"state entry '{k}' is missing or has the wrong shape")
        self.state = {k: v.to(self.device).clone() for k, v in state.items()}


def resolve_device(device: str | torch.device) -> torch.device:
    """``device`` as a torch.device, or a ConfigError naming what is wrong with it (unknown,
    not cpu/cuda, or cuda on a machine without a CUDA GPU)."""
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError):
        raise ConfigError(f"unknown device '{device}'") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ConfigError("device 'cuda' asked for, but no CUDA GPU is available")
    if dev.type not in ("cpu", "cuda"):
        raise ConfigError(f"device must be cpu or cuda, got '{device}'")
    return dev


class _Fused:
    """A function under ``torch.compile`` (one fused graph, static shapes), falling back to the
    eager function, with a warning, if compilation fails on this machine."""

    def __init__(self, fn) -> None:
        self.eager = fn
        self.fused = torch.compile(fn, fullgraph=True, dynamic=False)
        self.failed = False

    def __call__(self, *args):
        if not self.failed:
            try:
                return self.fused(*args)
            except Exception as exc:  # noqa: BLE001 - a broken compiler means "run eagerly"
                warnings.warn(
                    f"torch.compile failed ({type(exc).__name__}: {exc}); running eagerly",
                    stacklevel=3,
                )
                self.failed = True
        return self.eager(*args)


def make_env(
    config: EnvConfig | dict[str, Any] | None = None,
    num_envs: int = 1,
    device: str | torch.device = "cpu",
    seed: int | None = None,
    **options: Any,
) -> PursuitEvasionEnv:
    """A batch of ``num_envs`` pursuit-evasion environments on ``device``.

    ``config`` is an :class:`EnvConfig`, a dict of its keys, or None for the defaults.
    Keyword ``options``: ``compile=True`` fuses the step with ``torch.compile`` (several times
    faster once compiled; the first step then takes tens of seconds), ``check_actions=False``
    skips the NaN check of actions (one host-device sync per step on CUDA),
    ``wait_kernels=True`` loads the compiled CPU kernels of the step before the first step
    (compiling them here, some 20-35 s once per machine, if none are cached) so that every step runs
    them. Without it, on a machine where they are not compiled yet, the first step does not
    wait: a background process compiles them and the steps run the torch code until it is
    done (the same physics up to float32 rounding; :mod:`pes.sim.kernels`).
    """
    unknown = set(options) - {"compile", "check_actions", "wait_kernels"}
    if unknown:
        raise ConfigError(f"unknown make_env options {sorted(unknown)}")
    return PursuitEvasionEnv(config, num_envs, device, seed, **options)

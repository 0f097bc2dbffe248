"""PettingZoo interface: ``pes.pettingzoo.parallel_env(**config)``.

===================== ==========================================================================
agents                ``pursuer_0`` ... ``pursuer_{N-1}`` (the evader runs its configured
                      policy inside the environment)
observation space     ``Box(-inf, inf, (N, 8), float32)`` per agent: its rows of Table I, self
                      first (see :func:`pes.sim.scenario.observe`); rows of dead pursuers are 0
action space          ``Box(-1, 1, (2,), float32)``: desired horizontal acceleration as a
                      fraction of the pursuer's maximum (clipped to norm 1)
state space           ``Box(-inf, inf, ((N + 1) * 8,), float32)``: the global state, flattened
rewards               eqs. (8)-(9) plus crash (-2) and capture (+5) rewards
termination           capture (all agents), too few pursuers left (all), or -- with
                      ``crash_mode="disable"`` or ``damaged=K`` -- the agent's own loss
truncation            after ``max_steps`` (all agents)
infos                 per agent: ``obs_mask`` (N,) bool, ``alive``, ``crashed``, ``distance``
                      (m), and the episode's ``success``, ``steps``, ``crashes``
render modes          ``rgb_array`` (top-down picture, as in ``pes render``)
===================== ==========================================================================

Arguments: every :class:`pes.EnvConfig` key (``num_pursuers=5``, ``disturbance=True``, ...),
plus ``render_mode`` and ``compile`` (fuse the step with ``torch.compile``: about ten times
faster per step, after a first step that compiles for tens of seconds, cached on disk for later
runs). Unknown keys raise :class:`pes.errors.ConfigError`.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from pettingzoo import ParallelEnv

from pes.errors import ActionError
from pes.sim.config import EnvConfig
from pes.sim.env import ACTION_LIMIT, make_env
from pes.sim.scenario import OBS_FEATURES


def parallel_env(
    render_mode: str | None = None, compile: bool = False, **config: Any
) -> PESParallelEnv:
    """A PettingZoo ``ParallelEnv`` of one pursuit-evasion game; see the module docstring."""
    return PESParallelEnv(render_mode=render_mode, compile=compile, **config)


class PESParallelEnv(ParallelEnv):
    """One pursuit-evasion game with the pursuers as PettingZoo agents."""

    metadata = {"name": "pes_v0", "render_modes": ["rgb_array"], "is_parallelizable": True}

    def __init__(
        self, render_mode: str | None = None, compile: bool = False, **config: Any
    ) -> None:
        self.config = EnvConfig.from_dict(config)
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.render_mode = render_mode
        self._env = make_env(self.config, num_envs=1, compile=compile)
        n = self.config.num_pursuers
        self.possible_agents = [f"pursuer_{i}" for i in range(n)]
        self.agents: list[str] = []
        self._index = {name: i for i, name in enumerate(self.possible_agents)}
        self._obs_space = spaces.Box(-np.inf, np.inf, (n, OBS_FEATURES), np.float32)
        self._action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.state_space = spaces.Box(-np.inf, np.inf, ((n + 1) * OBS_FEATURES,), np.float32)
        self._state: np.ndarray | None = None
        self._frame: dict[str, Any] | None = None

    @functools.cache  # noqa: B019 - one space object per agent, as required
    def observation_space(self, agent: str) -> spaces.Box:
        return self._obs_space

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> spaces.Box:
        return self._action_space

    def reset(self, seed: int | None = None, options: dict | None = None):
        obs, info = self._env.reset(seed=seed)
        alive = info["alive"][0].cpu().numpy()
        self.agents = [a for a in self.possible_agents if alive[self._index[a]]]
        obs_np = obs[0].cpu().numpy()
        mask = info["obs_mask"][0].cpu().numpy()
        self._state = info["state"][0].cpu().numpy().reshape(-1)
        self._remember_frame(self._env.positions[0], alive, np.zeros_like(alive))
        infos = {a: {"obs_mask": mask[self._index[a]]} for a in self.agents}
        return {a: obs_np[self._index[a]] for a in self.agents}, infos

    def step(self, actions: dict[str, Any]):
        if not self.agents:
            raise ActionError("the episode is over: call reset()")
        if not isinstance(actions, dict):
            raise ActionError(
                f"actions must be a dict of agent name to action, got {type(actions).__name__}"
            )
        for agent in actions:
            if agent not in self._index:
                raise ActionError(f"unknown agent {agent!r}")
        n = self.config.num_pursuers
        joint = np.zeros((1, n, 2), dtype=np.float32)
        for agent in self.agents:
            if agent not in actions:
                raise ActionError(f"no action for live agent '{agent}'")
            joint[0, self._index[agent]] = _agent_action(agent, actions[agent])
        _, reward, terminated, truncated, info = self._env.step(torch.from_numpy(joint))
        # The episode's last observation, not the next episode's first (the batched
        # environment resets itself).
        obs = info["final_obs"][0].cpu().numpy()
        mask = info["final_obs_mask"][0].cpu().numpy()
        reward = reward[0].cpu().numpy()
        alive = info["alive"][0].cpu().numpy()
        crashed = info["crashed"][0].cpu().numpy()
        distances = info["distances"][0].cpu().numpy()
        ended, cut = bool(terminated[0]), bool(truncated[0])
        self._state = info["final_state"][0].cpu().numpy().reshape(-1)
        self._remember_frame(info["positions"][0], alive, crashed)
        episode = {
            "success": bool(info["success"][0]),
            "steps": int(info["steps"][0]),
            "crashes": int(info["crashes"][0]),
        }
        acting = list(self.agents)
        observations, rewards, terminations, truncations, infos = {}, {}, {}, {}, {}
        for agent in acting:
            i = self._index[agent]
            observations[agent] = obs[i]
            rewards[agent] = float(reward[i])
            terminations[agent] = ended or not bool(alive[i])
            truncations[agent] = cut and not terminations[agent]
            infos[agent] = {
                "obs_mask": mask[i],
                "alive": bool(alive[i]),
                "crashed": bool(crashed[i]),
                "distance": float(distances[i]),
                **episode,
            }
        self.agents = [a for a in acting if not (terminations[a] or truncations[a])]
        return observations, rewards, terminations, truncations, infos

    def state(self) -> np.ndarray:
        """The global state ((N + 1) * 8,) after the last reset or step."""
        if self._state is None:
            raise ActionError("call reset() first")
        return self._state

    def _remember_frame(
        self, positions: torch.Tensor, alive: np.ndarray, crashed: np.ndarray
    ) -> None:
        self._frame = {
            "t": 0.0,
            "pos": positions.cpu().tolist(),
            "alive": [bool(a) for a in alive],
            "crashed": [bool(c) for c in crashed],
        }

    def render(self) -> np.ndarray | None:
        """An RGB picture (H, W, 3) of the arena from above, with ``render_mode="rgb_array"``."""
        if self.render_mode is None or self._frame is None:
            return None
        from pes.record.render import render_frames

        layout = self._env.layout
        record = {
            "arena": [layout.width, layout.height],
            "buildings": layout.boxes.tolist(),
            "agents": [{"id": a, "role": "pursuer"} for a in self.possible_agents]
            + [{"id": "evader", "role": "evader"}],
            "body_radius": self.config.body_radius,
            "capture_radius": self.config.capture_radius,
            "frames": [self._frame],
            "outcome": {},
        }
        image = next(render_frames(record, trail=0))
        return np.asarray(image)

    def close(self) -> None:
        self.agents = []


def _agent_action(agent: str, action: Any) -> np.ndarray:
    """``action`` as a finite float32 array of shape (2,), or an :class:`ActionError` naming
    ``agent``: no broadcasting of a scalar, no reading of strings as numbers."""
    if isinstance(action, torch.Tensor):
        if action.dtype == torch.bool or action.is_complex():
            raise ActionError(f"action of {agent} must be real numbers, got {action.dtype}")
        action = action.detach().to("cpu", torch.float64).numpy()  # also bfloat16
    if isinstance(action, (str, bytes, dict)):
        raise ActionError(
            f"action of {agent} must be 2 numbers (array of shape (2,)), got "
            f"{type(action).__name__}"
        )
    try:
        array = np.asarray(action)
    except (TypeError, ValueError):
        raise ActionError(f"action of {agent} must be an array of shape (2,)") from None
    if array.dtype.kind not in "fiu":
        raise ActionError(f"action of {agent} must be numbers, got dtype {array.dtype}")
    if array.shape != (2,):
        raise ActionError(f"action of {agent} must have shape (2,), got {array.shape}")
    array = array.astype(np.float64)
    if not np.all(np.isfinite(array)):
        raise ActionError(f"action of {agent} holds NaN or infinite values: {array.tolist()}")
    if np.any(np.abs(array) > ACTION_LIMIT):
        raise ActionError(
            f"action of {agent} is {array.tolist()}: actions are fractions of the maximum "
            f"acceleration, in [-1, 1] (clipped to norm 1), and may not exceed {ACTION_LIMIT:g}"
        )
    return array.astype(np.float32)

"""Gymnasium interface: the pursuer team as one agent with a joint action.

``PursuitEvasionGym(**config)`` is a ``gymnasium.Env`` of one game, registered as
``"pes/PursuitEvasion-v0"``; ``PursuitEvasionVector(num_envs, **config)`` is a
``gymnasium.vector.VectorEnv`` over the batched simulator (NumPy in and out; auto-reset in the
same step, the final observation in ``info["final_obs"]``).

=================== =============================================================================
observation space   ``Box(-inf, inf, (N, N, 8), float32)``: every pursuer's rows of Table I
action space        ``Box(-1, 1, (N, 2), float32)``: one desired acceleration per pursuer
reward              the mean over pursuers alive at the step's start of eqs. (8)-(9) + crash and
                    capture rewards (``info["rewards"]`` holds each pursuer's)
terminated          capture, or fewer pursuers left than ``capture_count``
truncated           after ``max_steps``
=================== =============================================================================

Arguments: every :class:`pes.EnvConfig` key, plus ``compile`` (see :func:`pes.make_env`).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv

from pes.pettingzoo import PESParallelEnv
from pes.sim.config import EnvConfig
from pes.sim.env import make_env
from pes.sim.scenario import OBS_FEATURES


def _spaces(config: EnvConfig) -> tuple[spaces.Box, spaces.Box]:
    n = config.num_pursuers
    return (
        spaces.Box(-np.inf, np.inf, (n, n, OBS_FEATURES), np.float32),
        spaces.Box(-1.0, 1.0, (n, 2), np.float32),
    )


def _team_reward(reward: torch.Tensor, alive_before: torch.Tensor) -> torch.Tensor:
    alive = alive_before.to(reward.dtype)
    return (reward * alive).sum(-1) / alive.sum(-1).clamp(min=1.0)


class PursuitEvasionGym(gym.Env):
    """One pursuit-evasion game, the pursuer team as a single Gymnasium agent."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self, render_mode: str | None = None, compile: bool = False, **config: Any
    ) -> None:
        # The PettingZoo env already knows how to draw; the game itself is the batched env.
        self._view = PESParallelEnv(render_mode=render_mode, **config) if render_mode else None
        self.config = EnvConfig.from_dict(config)
        self.render_mode = render_mode
        self.observation_space, self.action_space = _spaces(self.config)
        self._env = make_env(self.config, num_envs=1, compile=compile)
        self._alive: torch.Tensor | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        obs, info = self._env.reset(seed=seed)
        self._alive = info["obs_mask"][:, :, 0]
        if self._view is not None:
            self._view.reset(seed=seed)
        return obs[0].numpy(), {"obs_mask": info["obs_mask"][0].numpy()}

    def step(self, action):
        joint = torch.as_tensor(np.asarray(action, dtype=np.float32)).unsqueeze(0)
        _, reward, terminated, truncated, info = self._env.step(joint)
        team = float(_team_reward(reward, self._alive)[0])
        self._alive = info["obs_mask"][:, :, 0]
        if self._view is not None:
            self._view._remember_frame(
                info["positions"][0], info["alive"][0].numpy(), info["crashed"][0].numpy()
            )
        out = {
            "rewards": reward[0].numpy(),
            "success": bool(info["success"][0]),
            "steps": int(info["steps"][0]),
            "crashes": int(info["crashes"][0]),
            "obs_mask": info["final_obs_mask"][0].numpy(),
        }
        return (info["final_obs"][0].numpy(), team, bool(terminated[0]), bool(truncated[0]), out)

    def render(self):
        return self._view.render() if self._view is not None else None


class PursuitEvasionVector(VectorEnv):
    """``num_envs`` games as a Gymnasium vector environment over the batched simulator."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(
        self, num_envs: int, device: str = "cpu", compile: bool = False, **config: Any
    ) -> None:
        self.config = EnvConfig.from_dict(config)
        self.num_envs = num_envs
        self._env = make_env(self.config, num_envs=num_envs, device=device, compile=compile)
        self.single_observation_space, self.single_action_space = _spaces(self.config)
        self.observation_space = gym.vector.utils.batch_space(
            self.single_observation_space, num_envs
        )
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, num_envs)
        self._alive: torch.Tensor | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self._env.reset(seed=seed)
        self._alive = info["obs_mask"][:, :, 0]
        return obs.cpu().numpy(), {"obs_mask": info["obs_mask"].cpu().numpy()}

    def step(self, actions):
        joint = torch.as_tensor(np.asarray(actions, dtype=np.float32), device=self._env.device)
        obs, reward, terminated, truncated, info = self._env.step(joint)
        team = _team_reward(reward, self._alive)
        self._alive = info["obs_mask"][:, :, 0]
        out = {
            k: info[k].cpu().numpy()
            for k in ("success", "steps", "crashes", "obs_mask", "final_obs")
        }
        out["rewards"] = reward.cpu().numpy()
        return (
            obs.cpu().numpy(),
            team.cpu().numpy(),
            terminated.cpu().numpy(),
            truncated.cpu().numpy(),
            out,
        )


gym.register(id="pes/PursuitEvasion-v0", entry_point=PursuitEvasionGym, max_episode_steps=None)

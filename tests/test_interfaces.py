"""PettingZoo and Gymnasium conformance."""

from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test

import pes.pettingzoo as pz
from pes.errors import ActionError, ConfigError


@pytest.mark.parametrize(
    "config",
    [
        {},
        {"crash_mode": "disable", "damaged": 1, "damage_step": "random", "max_steps": 150},
        {"num_pursuers": 1, "capture_count": 1, "max_steps": 80},
        {"num_pursuers": 8, "max_steps": 60, "dynamics": "point_mass"},
    ],
)
def test_parallel_api(config):
    parallel_api_test(pz.parallel_env(**config), num_cycles=600)


def test_parallel_seed():
    parallel_seed_test(lambda: pz.parallel_env(disturbance=True, max_steps=80), num_cycles=100)


def test_agents_leave_when_damaged():
    env = pz.parallel_env(crash_mode="disable", damaged=2)
    obs, infos = env.reset(seed=0)
    assert len(env.agents) == 3 and len(env.possible_agents) == 5
    assert set(obs) == set(env.agents)
    state = env.state()
    assert state.shape == env.state_space.shape


def test_bad_input():
    with pytest.raises(ConfigError, match="did you mean"):
        pz.parallel_env(num_pursuer=3)
    env = pz.parallel_env()
    env.reset(seed=0)
    with pytest.raises(ActionError, match="no action"):
        env.step({"pursuer_0": np.zeros(2)})
    with pytest.raises(ActionError, match="unknown agent"):
        env.step({a: np.zeros(2) for a in env.agents} | {"evader": np.zeros(2)})


def test_render_rgb_array():
    env = pz.parallel_env(render_mode="rgb_array")
    env.reset(seed=0)
    env.step({a: env.action_space(a).sample() for a in env.agents})
    image = env.render()
    assert image.ndim == 3 and image.shape[2] == 3 and image.std() > 10


def test_gymnasium_env_checker():
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    import pes.gymnasium as pg

    check_env(pg.PursuitEvasionGym(max_steps=50), skip_render_check=True)
    env = gym.make("pes/PursuitEvasion-v0", num_pursuers=3)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (3, 3, 8)


def test_gymnasium_vector():
    import pes.gymnasium as pg

    env = pg.PursuitEvasionVector(4, max_steps=10)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (4, 5, 5, 8)
    done = 0
    for _ in range(12):
        obs, reward, term, trunc, info = env.step(env.action_space.sample())
        done += int((term | trunc).sum())
    assert reward.shape == (4,) and done == 4 and info["final_obs"].shape == (4, 5, 5, 8)

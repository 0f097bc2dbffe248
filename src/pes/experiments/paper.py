"""The paper's reported numbers (Zhang et al., TNNLS 2022, §V), set beside ours."""

from __future__ import annotations

METHODS = ("pid-pf", "ppo", "mappo", "ddpg", "maddpg", "bicnet", "maac", "cbc", "cbc-tp")
"""Table IV's columns in the paper's order, with MAPPO (Yu et al., 2022: the standard
centralised-value PPO, not in the paper) after PPO and the CBC Net ablation (§V-C) before
CBC-TP."""

LABELS = {
    "pid-pf": "PID(PF)",
    "ppo": "PPO",
    "mappo": "MAPPO",
    "ddpg": "DDPG",
    "maddpg": "MADDPG",
    "bicnet": "BiCNet",
    "maac": "MAAC",
    "cbc": "CBC Net",
    "cbc-tp": "CBC-TP Net",
}

TABLE4: dict[str, dict[str, float | None]] = {
    "pid-pf": {"success_rate": 0.273, "mean_steps": 482, "mean_reward": None},
    "ppo": {"success_rate": 0.706, "mean_steps": 362, "mean_reward": -0.35},
    "mappo": {"success_rate": None, "mean_steps": None, "mean_reward": None},
    "ddpg": {"success_rate": 0.568, "mean_steps": 412, "mean_reward": -0.42},
    "maddpg": {"success_rate": 0.966, "mean_steps": 208, "mean_reward": -0.28},
    "bicnet": {"success_rate": 0.906, "mean_steps": 265, "mean_reward": -0.33},
    "maac": {"success_rate": 0.98, "mean_steps": 140, "mean_reward": -0.23},
    "cbc": {"success_rate": None, "mean_steps": None, "mean_reward": None},
    "cbc-tp": {"success_rate": 0.988, "mean_steps": 132, "mean_reward": -0.21},
}
"""Table IV: 1000 episodes with disturbance against the DDPG evader (CBC Net and MAPPO are not
in it)."""

TABLE5 = {
    "fde": (0.026, 0.038, 0.062, 0.118, 0.196),
    "ade": (0.026, 0.032, 0.042, 0.061, 0.088),
}
"""Table V: TP Net's normalised final / average displacement error for k = 1 ... 5."""

TABLE6 = {0: (0.988, 132), 1: (0.956, 212), 2: (0.867, 308)}
"""Table VI: CBC-TP Net with 0 / 1 / 2 pursuers damaged -> (success rate, episode steps)."""

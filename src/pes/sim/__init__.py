"""The simulator: scenario configuration, layouts, dynamics, and the batched environment."""

from pes.sim.config import EnvConfig
from pes.sim.env import PursuitEvasionEnv, make_env

__all__ = ["EnvConfig", "PursuitEvasionEnv", "make_env"]

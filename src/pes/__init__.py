"""PES: multi-quadcopter pursuit-evasion (Zhang et al., "Game of Drones", TNNLS 2022).

The simulator is :func:`make_env` over an :class:`EnvConfig`; the PettingZoo interface is
:func:`pes.pettingzoo.parallel_env`; the command line is ``pes``.
"""

from pes.errors import PESError
from pes.sim.config import EnvConfig
from pes.sim.env import PursuitEvasionEnv, make_env

__version__ = "0.1.0"

# The methods register the loader of the shipped DDPG evader with the simulator (which imports
# no learner): ``evader_policy="ddpg"`` works from ``import pes`` on.
import pes.algos  # noqa: E402, F401

__all__ = ["EnvConfig", "PESError", "PursuitEvasionEnv", "__version__", "make_env"]

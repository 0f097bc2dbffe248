"""PES: multi-quadcopter pursuit-evasion (Zhang et al., "Game of Drones", TNNLS 2022).

The simulator is :func:`make_env` over an :class:`EnvConfig`; the PettingZoo interface is
:func:`pes.pettingzoo.parallel_env`; the command line is ``pes``.
"""

from pes.errors import PESError
from pes.sim.config import EnvConfig
from pes.sim.env import PursuitEvasionEnv, make_env

__version__ = "0.1.0"

__all__ = ["EnvConfig", "PESError", "PursuitEvasionEnv", "__version__", "make_env"]

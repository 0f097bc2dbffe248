"""The registry of methods: ``--algo`` name -> learner class. Adding a method is one file
under ``pes/algos/`` and one entry here (docs/algorithms/write_your_own.md)."""

from __future__ import annotations

from pes.algos.bicnet import BiCNet
from pes.algos.cbc_tp import CBCTP, CBCNet
from pes.algos.ddpg import DDPG
from pes.algos.evader_ddpg import EvaderDDPG
from pes.algos.maac import MAAC
from pes.algos.maddpg import MADDPG
from pes.algos.mappo import MAPPO
from pes.algos.ppo import PPO
from pes.errors import ConfigError
from pes.learn.learner import Learner

ALGOS: dict[str, type[Learner]] = {
    cls.name: cls for cls in (CBCTP, CBCNet, MADDPG, DDPG, PPO, MAPPO, BiCNet, MAAC, EvaderDDPG)
}
"""Method name -> learner class."""

PURSUER_ALGOS = tuple(name for name, cls in ALGOS.items() if cls.pursuer)
"""Methods whose policy controls the pursuers (``pes eval --policy``)."""

TABLE4_ALGOS = ("ppo", "ddpg", "maddpg", "bicnet", "maac", "cbc-tp")
"""The learners of the paper's Table IV (PID(PF), its seventh method, does not learn)."""


def learner_class(algo: str) -> type[Learner]:
    """The learner of method ``algo``, or a one-line error listing the methods."""
    if algo not in ALGOS:
        raise ConfigError(f"algo must be one of {', '.join(ALGOS)}, got '{algo}'")
    return ALGOS[algo]

"""Learning algorithms on one shared machinery (SPEC §3).

``ALGOS`` maps each ``pes train --algo`` name to its learner class. Every learner has the same
surface, used by :func:`pes.algos.trainer.train`: ``adapt_env``, ``act``, ``record``,
``episode_reset``, ``ready``, ``update``, ``modules``, ``optimizers``, ``policy_modules`` and a
``buffer`` (:class:`pes.algos.buffer.ReplayBuffer`).
"""

from __future__ import annotations

from pes.algos.bicnet import BiCNet
from pes.algos.cbc_tp import CBCTP
from pes.algos.ddpg import DDPG
from pes.algos.evader_ddpg import EvaderDDPG
from pes.algos.maddpg import MADDPG

ALGOS = {
    "cbc-tp": CBCTP,
    "cbc": CBCTP,
    "maddpg": MADDPG,
    "ddpg": DDPG,
    "bicnet": BiCNet,
    "evader-ddpg": EvaderDDPG,
}
"""Algorithm name -> learner class (``cbc`` is CBC-TP Net with ``use_tp=False``)."""

PURSUER_ALGOS = ("cbc-tp", "cbc", "maddpg", "ddpg", "bicnet")
"""Algorithms whose policy controls the pursuers (``pes eval --policy``)."""

__all__ = ["ALGOS", "PURSUER_ALGOS"]

"""Learning algorithms on one shared machinery (SPEC §3).

``ALGOS`` maps each ``pes train --algo`` name to its learner class. Every learner has the same
surface, used by :func:`pes.algos.trainer.train`: ``adapt_env``, ``act``, ``record``,
``episode_reset``, ``ready``, ``update``, ``score``, ``modules``, ``optimizers``,
``policy_modules``, a ``buffer`` (:class:`pes.algos.buffer.ReplayBuffer`, or
:class:`pes.algos.buffer.RolloutBuffer` for on-policy learners, which set ``on_policy = True``)
and a ``noise`` process (None where the policy explores by sampling). Pursuer learners also have
``build_policy`` (used by :func:`pes.algos.policy.load_pursuer_policy`).
"""

from __future__ import annotations

from pes.algos.bicnet import BiCNet
from pes.algos.cbc_tp import CBCTP
from pes.algos.ddpg import DDPG
from pes.algos.evader_ddpg import EvaderDDPG
from pes.algos.maac import MAAC
from pes.algos.maddpg import MADDPG
from pes.algos.ppo import PPO

ALGOS = {
    "cbc-tp": CBCTP,
    "cbc": CBCTP,
    "maddpg": MADDPG,
    "ddpg": DDPG,
    "ppo": PPO,
    "bicnet": BiCNet,
    "maac": MAAC,
    "evader-ddpg": EvaderDDPG,
}
"""Algorithm name -> learner class (``cbc`` is CBC-TP Net with ``use_tp=False``)."""

PURSUER_ALGOS = ("cbc-tp", "cbc", "maddpg", "ddpg", "ppo", "bicnet", "maac")
"""Algorithms whose policy controls the pursuers (``pes eval --policy``)."""

__all__ = ["ALGOS", "PURSUER_ALGOS"]

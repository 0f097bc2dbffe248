"""Pursuer policies that need no learning: ``random`` and the PID(PF) baseline of Table IV.

Every policy follows :class:`Policy`: ``policy(obs, info) -> actions`` with the observations of
:class:`pes.sim.env.PursuitEvasionEnv` and actions shaped (num_envs, N, 2) in [-1, 1], and
``policy.reset(mask)`` to clear the memory of the environments that start a new episode.
"""

from pes.policies.base import Policy
from pes.policies.pid_pf import PIDPotentialField
from pes.policies.random import RandomPolicy

SCRIPTED = {"random": RandomPolicy, "pid-pf": PIDPotentialField}
"""Name -> class of the policies that need no training (``pes eval --policy NAME``)."""

__all__ = ["SCRIPTED", "PIDPotentialField", "Policy", "RandomPolicy"]

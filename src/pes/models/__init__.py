"""Trained policies shipped with PES (policy files and their model cards).

* ``evader_ddpg.pt`` / ``evader_ddpg.md``: the frozen DDPG evader (``evader_policy="ddpg"``);
* ``cbc_tp.pt`` / ``cbc_tp.md``: a CBC-TP Net swarm (``pes eval --policy cbc-tp``).

Load them with :func:`pes.algos.policy.load_pursuer_policy` /
:func:`pes.algos.policy.load_evader_actor` by name.
"""

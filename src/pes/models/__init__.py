"""Trained policies shipped with PES (policy files and their model cards).

* ``evader_ddpg_paper.pt`` / ``evader_ddpg_paper.md``: the default frozen DDPG evader
  (``evader_policy="ddpg"``, ``evader_model="evader-ddpg-paper"``), calibrated to the paper's;
* ``evader_ddpg.pt`` / ``evader_ddpg.md``: the fully trained DDPG evader, far stronger
  (``evader_model="evader-ddpg"``);
* ``cbc_tp.pt`` / ``cbc_tp.md``: a CBC-TP Net swarm (``pes eval --policy cbc-tp``).

Load them with :func:`pes.algos.policy.load_pursuer_policy` /
:func:`pes.algos.policy.load_evader_actor` by name.
"""

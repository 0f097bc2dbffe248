"""The learning machinery that knows no method: the :class:`~pes.learn.learner.Learner`
interface, the training loop (:mod:`pes.learn.trainer`), configurations and training protocols,
replay and rollout buffers, TD targets, the deterministic actor-critic of the DDPG family,
noise, network building blocks and checkpoints. The methods live in :mod:`pes.algos`."""

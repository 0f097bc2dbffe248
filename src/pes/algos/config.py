"""``TrainConfig``: every setting of a training run, with the ``paper`` and ``quick`` presets.

A run's configuration is built in layers: the dataclass defaults, then the preset of its
algorithm and budget (:data:`PRESETS`; none for ``--preset none``, which re-runs a recorded
``config.yaml`` as it was), then a YAML file (``--config``), then ``--set key=value``
overrides. Scenario settings go under ``env`` (``--set env.disturbance=true``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

from pes.config import from_dict, to_dict
from pes.errors import ConfigError
from pes.sim.config import EnvConfig

Budget = Literal["paper", "quick", "tiny", "none"]


@dataclass
class TrainConfig:
    """A training run. Times are in minutes, rates in transitions (one environment step of one
    environment is one transition)."""

    algo: str = "cbc-tp"
    """Algorithm (see ``pes train --help``)."""
    preset: Budget = "quick"
    """Budget preset applied under the user's settings: ``paper`` (the paper's settings),
    ``quick`` (tuned to learn on a laptop CPU), ``tiny`` (tests) or ``none`` (the defaults
    below alone: a run's saved ``config.yaml`` applied as it was recorded, whatever the presets
    have become since; a key the file predates takes its default, as on ``--resume``)."""
    env: dict[str, Any] = field(default_factory=dict)
    """Scenario settings (:class:`pes.EnvConfig` keys) for the training environments."""
    seed: int = 0
    """Seed of the environments, the network initialisation, the noise and the sampling."""
    device: str = "cpu"
    """``cpu`` or ``cuda``."""
    threads: int = 0
    """Torch CPU threads (0 = torch's default)."""
    compile_env: bool = True
    """Fuse the simulator step with ``torch.compile`` (eager fallback if it fails)."""

    # --- budget ------------------------------------------------------------------------------
    episodes: int = 4000
    """Training episodes (finished episodes, summed over all environments)."""
    time_limit: float = 0.0
    """Stop after this many minutes of training (0 = no limit); a checkpoint is written."""
    num_envs: int = 1
    """Environments collected from at once."""

    # --- networks (Table II) -------------------------------------------------------------------
    hidden: int = 256
    """Units of the actor's and the critic's bidirectional LSTM (each direction)."""
    mlp_hidden: int = 64
    """Units of the MLP after the LSTM (MADDPG, DDPG: of each of their MLPs' two hidden
    layers)."""
    tp_hidden: int = 256
    """Units of each TP Net LSTM layer."""
    tp_layers: int = 2
    """TP Net LSTM layers."""
    horizon: int = 3
    """k: future evader positions TP Net predicts (the actor sees 2k numbers)."""
    use_tp: bool = True
    """Use TP Net (False gives CBC Net, the ablation of §V-C)."""
    shared: bool = True
    """One actor and one critic for all pursuers (False: one per pursuer, as Algorithm 1)."""
    obstacle_scale: float = 20.0
    """Factor on the obstacle-vector columns of the observation rows before the actor and the
    critic: in arena units the 2 m safety margin is only 0.02 (see ``nets.RowScaled``)."""
    target_scale: float = 5.0
    """Factor on the vector to the evader and on TP Net's relative prediction before the actor
    and the critic."""

    # --- learning (§V-A) -----------------------------------------------------------------------
    gamma: float = 0.95
    lr_actor: float = 1e-3
    lr_critic: float = 1e-3
    lr_tp: float = 1e-3
    tau: float = 1e-2
    """Soft target update rate."""
    n_step: int = 1
    """Transitions summed in a TD target before it bootstraps (n-step returns, as D4PG and
    DDPGfD; 1 = the paper's one-step target), for the OU-noise pursuer learners. The sum stops
    early where the episode ends or a pursuer leaves the game; the stored actions are not
    corrected for having been older policies' (they are off-policy, as D4PG's)."""
    buffer_size: int = 1_000_000
    """Transitions kept in the replay buffer."""
    batch_size: int = 512
    """Minibatch of the critic and actor updates (M)."""
    tp_batch_size: int = 512
    """Minibatch of the TP Net updates (J)."""
    update_every: int = 50
    """Collected transitions per gradient update (the paper updates every 50)."""
    tp_update_every: int = 1
    """Critic/actor updates per TP Net update (TP Net converges long before the others)."""
    warmup: int = 5000
    """Transitions collected before the first update."""
    actor_gradient: str = "one"
    """Actor update of CBC-TP: ``one`` (one random alive pursuer per sample takes the current
    actor's action, the others keep their stored ones, as MADDPG) or ``all`` (every alive
    pursuer takes it at once; the actor ascends the mean of their Qs)."""
    charge_exits: bool = False
    """CBC-TP, for training with ``env.crash_mode=disable``: a pursuer that leaves the game --
    disabled by a crash, or in an episode that fails with too few pursuers left -- gets as TD
    target its reward plus its last step's reward (crash term aside) for every step to come
    (discounted), instead of nothing: with every step's reward negative, leaving must not pay."""
    grad_clip: float = 1.0
    """Gradient norm clip (0 = none)."""
    action_reg: float = 1e-3
    """Weight of the squared action in the actor loss (CBC-TP: the squared pre-tanh output, as
    MADDPG regularises it, so that the tanh does not saturate)."""

    # --- exploration -----------------------------------------------------------------------------
    noise_theta: float = 0.15
    noise_sigma: float = 0.2
    """OU noise scale at the start of training."""
    noise_sigma_final: float = 0.2
    """OU noise scale reached (linearly) after ``noise_decay`` of the episodes."""
    noise_decay: float = 0.5
    """Fraction of the episodes over which the noise scale decays."""
    greedy_envs: float = 0.0
    """Share (0-1) of the environments that act without exploration noise (the OU-noise pursuer
    learners: CBC-TP, CBC Net, MADDPG, DDPG, BiCNet): their episodes show the current policy's
    own captures, which noise destroys (OU noise of scale 0.2 takes PID(PF) from 52 % to 3 %
    captures against the evader capped at 8 m/s)."""

    # --- PPO (on-policy; docs/algorithms/ppo.md) ---------------------------------------------
    rollout_steps: int = 128
    """PPO: vector steps per rollout (a rollout holds ``rollout_steps * num_envs`` transitions,
    each with N pursuer samples); ``batch_size`` is the minibatch in transitions."""
    ppo_epochs: int = 10
    """PPO: passes over each rollout."""
    gae_lambda: float = 0.95
    """PPO: lambda of generalised advantage estimation."""
    clip_coef: float = 0.2
    """PPO: clipping range of the probability ratio."""
    ent_coef: float = 0.0
    """PPO: weight of the entropy bonus in the actor loss."""
    target_kl: float = 0.0
    """PPO: stop a rollout's epochs once the approximate KL exceeds this (0 = never)."""
    log_std_init: float = -0.5
    """PPO: initial log standard deviation of the Gaussian policy (in action units)."""

    # --- MAAC (soft actor-critic with an attention critic; docs/algorithms/maac.md) ----------
    attention_heads: int = 4
    """MAAC: attention heads of the critic (``hidden`` must be a multiple)."""
    alpha: float = 0.05
    """MAAC: initial entropy temperature (SAC's 0.2 explored too long in the learning test)."""
    auto_alpha: bool = True
    """MAAC: tune the temperature towards ``target_entropy`` (SAC v2); False keeps ``alpha``."""
    target_entropy: float = -2.0
    """MAAC: target entropy per pursuer (nats; -2 = minus the action dimension)."""
    lr_alpha: float = 1e-3
    """MAAC: learning rate of the temperature."""
    attend_reg: float = 1e-3
    """MAAC: weight of the squared attention logits in the critic loss (as the original)."""

    # --- curriculum and warm start --------------------------------------------------------------
    curriculum_speed: float = 0.0
    """Evader-speed curriculum (m/s; 0 = off): the evader starts capped at this speed and the cap
    rises by ``curriculum_step`` whenever a log row's training success rate reaches
    ``curriculum_success``, up to ``env.evader_max_speed``. Evaluations use the full speed."""
    curriculum_step: float = 0.5
    """Evader-speed curriculum: m/s added at each raise."""
    curriculum_success: float = 0.3
    """Evader-speed curriculum: training success rate (0-1) of a log row that raises the cap."""
    disable_crashes_at: float = 0.0
    """Crash-rule curriculum of the off-policy pursuer learners (0 = off): training starts
    with ``env.crash_mode=continue`` and, once a log row's training success rate reaches this
    (0-1), crashes disable the pursuer for the rest of the run, as in every evaluation (pair it
    with ``charge_exits``). Crashes that disable from the first episode teach a swarm to stay
    alive rather than to chase."""
    init_from: str = ""
    """Start every network (and target network) from this run's ``checkpoint.pt`` (same
    algorithm and architecture); optimisers, replay buffer, noise and counters start fresh.
    A policy file or a shipped model's name (``cbc-tp``) gives only the acting networks (and
    their target copies): the critic starts fresh, so pair it with ``critic_warmup``."""
    anchor_weight: float = 0.0
    """CBC-TP, CBC Net, BiCNet with ``init_from``: keep the actor near the one the run started
    from. The actor loss becomes TD3+BC's (Fujimoto & Gu 2021) with the starting actor as the
    demonstrator: minus the Q term over the batch's mean |Q|, plus this weight times the squared
    distance between the actor's action and the starting actor's (0 = off)."""
    critic_warmup: int = 0
    """Updates, counted from the run's start, that train the critic (and TP Net) but not the
    actor (OU-noise pursuer learners): a fresh critic first learns the values of a trained
    actor (``init_from`` a policy file) before its gradient steers that actor."""

    # --- demonstrations (CBC-TP, CBC Net, BiCNet) ------------------------------------------------
    demo_policy: str = ""
    """A scripted pursuer policy (``pid-pf``) that plays the first ``demo_transitions``
    transitions of a run ("" = none), without exploration noise (OU noise of scale 0.2 takes
    PID(PF) from 52 % to 3 % captures against the evader capped at 8 m/s); its transitions are
    marked in the replay buffer as demonstrations (as DDPGfD, Vecerik et al. 2017)."""
    demo_transitions: int = 0
    """Transitions the demonstration policy plays (at most ``buffer_size``; the buffer holds
    whole steps of all environments, so at most its capacity rounded down to them)."""
    bc_weight: float = 0.0
    """Weight of the behaviour-cloning term of the actor loss: the squared distance between the
    actor's and the demonstrated action, on the demonstration samples of each minibatch, beside
    the Q term divided by the batch's mean |Q| (TD3+BC, Fujimoto & Gu 2021). While the
    demonstrator still plays, the actor learns by this term alone. It fades as the
    demonstrations leave the replay buffer. (The Q-filter of Nair et al. 2018,
    cloning only where the critic rates the demonstration higher, pushed the actor away from
    PID(PF) while the critic was young: not used.)"""

    # --- opponent (evader training) ---
    opponent: str = "pid-pf"
    """Pursuers the DDPG evader trains against (``pid-pf`` or ``random``)."""

    # --- logging and checkpoints ---
    log_every: int = 100
    """Episodes per log row (success rate every 100 episodes, as Fig. 6)."""
    checkpoint_every: float = 5.0
    """Minutes between checkpoints (one is also written at the end)."""
    checkpoint_buffer: bool = True
    """Save the replay buffer's contents in checkpoints (exact resumption)."""
    snapshots: bool = False
    """Also keep the policy of every log row as ``snapshots/ep<episodes>.pt`` (to choose an
    opponent of a given strength afterwards, as the shipped evader was chosen)."""
    eval_episodes: int = 100
    """Episodes of the evaluation at the end of training (0 = none)."""
    tensorboard: bool = True
    """Also write TensorBoard logs (needs the ``tensorboard`` package)."""

    def validate(self) -> None:
        from pes.algos import ALGOS  # noqa: PLC0415 - the registry imports this module

        if self.algo not in ALGOS:
            raise ConfigError(f"algo must be one of {', '.join(ALGOS)}, got '{self.algo}'")
        positive = (
            "episodes",
            "num_envs",
            "hidden",
            "mlp_hidden",
            "tp_hidden",
            "tp_layers",
            "horizon",
            "buffer_size",
            "batch_size",
            "tp_batch_size",
            "update_every",
            "tp_update_every",
            "n_step",
            "log_every",
            "rollout_steps",
            "ppo_epochs",
            "attention_heads",
        )
        for name in positive:
            if getattr(self, name) < 1:
                raise ConfigError(f"{name} must be at least 1, got {getattr(self, name)}")
        for name in (
            "time_limit",
            "warmup",
            "grad_clip",
            "action_reg",
            "obstacle_scale",
            "target_scale",
            "noise_sigma",
            "noise_sigma_final",
            "checkpoint_every",
            "eval_episodes",
            "threads",
            "ent_coef",
            "target_kl",
            "alpha",
            "lr_alpha",
            "attend_reg",
            "bc_weight",
            "critic_warmup",
            "anchor_weight",
        ):
            if getattr(self, name) < 0:
                raise ConfigError(f"{name} must be non-negative, got {getattr(self, name)}")
        if not 0.0 <= self.gamma < 1.0:
            raise ConfigError(f"gamma must be in [0, 1), got {self.gamma}")
        for name in ("gae_lambda", "clip_coef"):
            if not 0.0 < getattr(self, name) <= 1.0:
                raise ConfigError(f"{name} must be in (0, 1], got {getattr(self, name)}")
        if self.algo == "maac" and self.hidden % self.attention_heads:
            raise ConfigError(
                f"hidden ({self.hidden}) must be a multiple of attention_heads "
                f"({self.attention_heads})"
            )
        if not 0.0 < self.tau <= 1.0:
            raise ConfigError(f"tau must be in (0, 1], got {self.tau}")
        if not 0.0 <= self.greedy_envs <= 1.0:
            raise ConfigError(f"greedy_envs must be in [0, 1], got {self.greedy_envs}")
        if not 0.0 < self.noise_decay <= 1.0:
            raise ConfigError(f"noise_decay must be in (0, 1], got {self.noise_decay}")
        if self.buffer_size < 2 * self.num_envs:
            raise ConfigError("buffer_size must hold at least two steps of every environment")
        if self.device not in ("cpu", "cuda"):
            raise ConfigError(f"device must be cpu or cuda, got '{self.device}'")
        if self.actor_gradient not in ("one", "all"):
            raise ConfigError(f"actor_gradient must be one or all, got '{self.actor_gradient}'")
        top_speed = self.env_config().evader_max_speed
        if self.curriculum_speed and not 0.0 < self.curriculum_speed <= top_speed:
            raise ConfigError(
                f"curriculum_speed must be 0 (off) or in (0, {top_speed:g}] m/s "
                f"(env.evader_max_speed), got {self.curriculum_speed}"
            )
        if self.curriculum_step <= 0:
            raise ConfigError(f"curriculum_step must be positive, got {self.curriculum_step}")
        if not 0.0 < self.curriculum_success <= 1.0:
            raise ConfigError(
                f"curriculum_success must be in (0, 1], got {self.curriculum_success}"
            )
        if not 0.0 <= self.disable_crashes_at <= 1.0:
            raise ConfigError(
                f"disable_crashes_at must be 0 (off) or in (0, 1], got {self.disable_crashes_at}"
            )
        if self.disable_crashes_at and self.env_config().crash_mode != "continue":
            raise ConfigError("disable_crashes_at needs env.crash_mode=continue to start from")
        if self.disable_crashes_at and self.algo in ("ppo", "evader-ddpg"):
            # PPO's rollout would run across the restart; the evader has no pursuers to lose
            raise ConfigError(
                f"disable_crashes_at is for the off-policy pursuer learners, not {self.algo}"
            )
        if self.demo_policy:
            if self.demo_policy != "pid-pf":
                raise ConfigError(f"demo_policy must be '' or pid-pf, got '{self.demo_policy}'")
            if self.algo not in ("cbc-tp", "cbc", "bicnet"):
                raise ConfigError(f"demo_policy is for cbc-tp, cbc and bicnet, not {self.algo}")
        if self.anchor_weight:
            if self.algo not in ("cbc-tp", "cbc", "bicnet"):
                raise ConfigError(f"anchor_weight is for cbc-tp, cbc and bicnet, not {self.algo}")
            if not self.init_from:
                raise ConfigError("anchor_weight keeps the actor near init_from's: set init_from")
        if not 0 <= self.demo_transitions <= self.buffer_size:
            raise ConfigError(
                f"demo_transitions must be in [0, buffer_size], got {self.demo_transitions}"
            )
        ou_learners = ("cbc-tp", "cbc", "maddpg", "ddpg", "bicnet")
        if self.n_step > 1 and self.algo not in ou_learners:
            raise ConfigError(
                f"n_step is for the OU-noise pursuer learners ({', '.join(ou_learners)}), "
                f"not {self.algo}"
            )
        for name in ("greedy_envs", "critic_warmup"):
            if getattr(self, name) and self.algo not in ou_learners:
                raise ConfigError(
                    f"{name} is for the OU-noise pursuer learners ({', '.join(ou_learners)}), "
                    f"not {self.algo}"
                )
        if self.opponent not in ("pid-pf", "random"):
            raise ConfigError(f"opponent must be pid-pf or random, got '{self.opponent}'")
        self.env_config()  # checks the scenario keys

    def env_config(self) -> EnvConfig:
        """The training scenario."""
        return EnvConfig.from_dict(dict(self.env))

    def to_dict(self) -> dict[str, Any]:
        return to_dict(self)


PAPER = dict(
    episodes=4000,
    num_envs=1,
    hidden=256,
    mlp_hidden=64,
    tp_hidden=256,
    gamma=0.95,
    lr_actor=1e-3,
    lr_critic=1e-3,
    lr_tp=1e-3,
    tau=1e-2,
    buffer_size=1_000_000,
    batch_size=512,
    tp_batch_size=512,
    update_every=50,
    warmup=5000,
    env=dict(evader_policy="ddpg"),
)
"""The paper's settings (§V-A), shared by every algorithm's ``paper`` preset."""

# The distance terms of eqs. (8)-(9) ten times heavier in training (evaluations use the paper's
# weights): see docs/algorithms/cbc_tp.md, "Training reward". The baselines' quick presets train
# with it and the same opponent, so that their Table IV rows and CBC-TP's old quick preset
# (QUICK_LEARNER) differ by the learner alone.
QUICK_ENV = dict(evader_policy="ddpg", self_weight=5.0, cooperation_weight=1.0)
QUICK_LEARNER = dict(
    episodes=2500,
    num_envs=32,
    hidden=64,
    mlp_hidden=64,
    tp_hidden=64,
    lr_actor=5e-4,
    lr_critic=1e-3,
    lr_tp=1e-3,
    buffer_size=300_000,
    batch_size=256,
    tp_batch_size=256,
    update_every=32,
    tp_update_every=4,
    warmup=10_000,
    noise_sigma=0.2,
    noise_sigma_final=0.05,
    noise_decay=0.6,
    time_limit=60.0,
    env=QUICK_ENV,
)
"""CBC-TP's quick preset until 2026-11-30 (its runs under ``results/training/`` dated before
then), and the base of the off-policy baselines' quick presets."""
QUICK = dict(
    QUICK_LEARNER,
    # 60 minutes bind, not the episodes (with n-step targets this 2-core CPU played 9123 in
    # 60 minutes with both cores); the noise falls from 0.2 to 0.05 over the first 1800
    episodes=10_000,
    noise_decay=0.18,
    # three-step TD targets: 94.6 % after 60 minutes with both cores where one-step ones gave
    # 77.1 % (docs/algorithms/cbc_tp.md, "N-step targets")
    n_step=3,
    greedy_envs=0.5,
    demo_policy="pid-pf",
    demo_transitions=100_000,
    # the demonstrations only fill the buffer: cloning them (bc_weight 2) was worse on both
    # seeds, and the cloned actor cannot fly (docs/algorithms/cbc_tp.md)
    bc_weight=0.0,
    disable_crashes_at=0.3,
    charge_exits=True,
    env=dict(
        QUICK_ENV,
        capture_reward=25.0,
        crash_reward=-10.0,
        safe_distance=1.5,
        approach_weight=0.3,
        disturbance=True,
    ),
)
"""CBC-TP's quick preset (a laptop CPU, 60 minutes): the learner of :data:`QUICK_LEARNER` with
three-step TD targets, PID(PF)'s demonstrations, half the environments without noise, the
training reward and disturbance of the shipped swarm's last stage, and crashes that disable
once a log row captures 30 % (docs/algorithms/cbc_tp.md, "The quick preset rebuilt" and
"N-step targets")."""

PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "cbc-tp": {
        "paper": PAPER,
        "quick": QUICK,
        "tiny": dict(
            episodes=40,
            num_envs=8,
            hidden=32,
            mlp_hidden=32,
            tp_hidden=32,
            buffer_size=20_000,
            batch_size=64,
            tp_batch_size=64,
            update_every=8,
            warmup=500,
            log_every=10,
            eval_episodes=20,
            checkpoint_every=0.5,
            env=dict(max_steps=100),
        ),
    },
    "evader-ddpg": {
        "paper": dict(PAPER, hidden=128),
        # Settings of the shipped evader (src/pes/models/evader_ddpg.md): with the paper's
        # gamma 0.95 and lr 5e-4 the evader's policy collapsed onto the arena wall (see
        # docs/algorithms/evader_ddpg.md).
        "quick": dict(
            episodes=1200,
            num_envs=32,
            hidden=128,
            gamma=0.99,
            lr_actor=1e-4,
            lr_critic=5e-4,
            action_reg=0.01,
            buffer_size=300_000,
            batch_size=256,
            update_every=16,
            warmup=10_000,
            noise_sigma=0.3,
            noise_sigma_final=0.1,
            noise_decay=0.6,
            time_limit=15.0,
            log_every=50,
        ),
        "tiny": dict(
            episodes=40,
            num_envs=8,
            hidden=32,
            buffer_size=20_000,
            batch_size=64,
            update_every=8,
            warmup=500,
            log_every=10,
            eval_episodes=20,
            checkpoint_every=0.5,
            env=dict(max_steps=100),
        ),
    },
}
TINY = dict(
    episodes=40,
    num_envs=8,
    hidden=32,
    buffer_size=20_000,
    batch_size=64,
    update_every=8,
    warmup=500,
    log_every=10,
    eval_episodes=20,
    checkpoint_every=0.5,
    env=dict(max_steps=100),
)
"""The shrunken settings of the tests, shared by the baselines' ``tiny`` presets."""
PRESETS["ppo"] = {
    # gamma, episodes and the minibatch from the paper (§V-A); the rest from the PPO paper
    # (Schulman et al., 2017, MuJoCo settings), as the paper gives none for its baselines.
    "paper": dict(
        PAPER,
        hidden=64,
        lr_actor=3e-4,
        lr_critic=3e-4,
        rollout_steps=2048,
        ppo_epochs=10,
        gae_lambda=0.95,
        clip_coef=0.2,
    ),
    # 64 environments x 64 steps per rollout, 4 minibatches, 10 epochs; ~1 s per update on
    # one CPU thread, about as long as the rollout's collection.
    "quick": dict(
        episodes=7000,
        num_envs=64,
        hidden=64,
        lr_actor=3e-4,
        lr_critic=1e-3,
        rollout_steps=64,
        batch_size=1024,
        ppo_epochs=10,
        time_limit=60.0,
        env=QUICK_ENV,
    ),
    "tiny": dict(TINY, rollout_steps=16, batch_size=32, ppo_epochs=4),
}
PRESETS["maac"] = {
    # The paper's settings (§V-A) where they apply; MAAC's own 128 units and 4 heads.
    "paper": dict(PAPER, hidden=128, attention_heads=4),
    # One update per 64 transitions (two vector steps of 32 environments): an update of the
    # two attention critics, the actors and alpha costs ~70 ms on one CPU thread.
    "quick": dict(
        episodes=1800,
        num_envs=32,
        hidden=64,
        attention_heads=4,
        lr_actor=5e-4,
        lr_critic=1e-3,
        buffer_size=300_000,
        batch_size=256,
        update_every=64,
        warmup=10_000,
        time_limit=60.0,
        env=QUICK_ENV,
    ),
    "tiny": dict(TINY, attention_heads=2),
}
PRESETS["cbc"] = {name: dict(values, use_tp=False) for name, values in PRESETS["cbc-tp"].items()}

# --- off-policy baselines (docs/algorithms/maddpg.md, ddpg.md, bicnet.md) -----------------------
# The paper gives no settings for its baselines: they take CBC-TP's (§V-A; quick: CBC-TP's quick
# learner and training reward, QUICK_LEARNER, without the aids of today's CBC-TP quick preset,
# so that their measured quick rows still hold), MADDPG's and DDPG's MLPs two hidden layers of
# mlp_hidden units.
# Quick budgets are episodes sized to ~20 minutes on one unloaded core: the MLP learners update
# twice as often (their updates are cheap); BiCNet's LSTMs cost ~5x more per update.
OFF_POLICY_QUICK = dict(QUICK_LEARNER, use_tp=False, time_limit=0.0)
OFF_POLICY_TINY = dict(PRESETS["cbc-tp"]["tiny"], use_tp=False)
PRESETS["maddpg"] = {
    "paper": dict(PAPER, use_tp=False, shared=False),
    "quick": dict(OFF_POLICY_QUICK, shared=False, episodes=3000, update_every=16),
    "tiny": dict(OFF_POLICY_TINY, shared=False),
}
PRESETS["ddpg"] = {name: dict(values) for name, values in PRESETS["maddpg"].items()}
PRESETS["bicnet"] = {
    "paper": dict(PAPER, use_tp=False, actor_gradient="all"),
    "quick": dict(OFF_POLICY_QUICK, actor_gradient="all", episodes=2000),
    "tiny": dict(OFF_POLICY_TINY, actor_gradient="all"),
}


def build_train_config(
    algo: str, preset: str = "quick", values: dict[str, Any] | None = None
) -> TrainConfig:
    """The configuration of ``algo`` under ``preset`` (``none``: the dataclass defaults), with
    ``values`` applied on top.

    ``values`` may hold an ``env`` mapping, merged key by key into the preset's.
    """
    if algo not in PRESETS:
        raise ConfigError(f"algo must be one of {', '.join(sorted(PRESETS))}, got '{algo}'")
    if preset != "none" and preset not in PRESETS[algo]:
        raise ConfigError(
            f"preset must be one of {', '.join(PRESETS[algo])} or none, got '{preset}'"
        )
    merged: dict[str, Any] = dict(PRESETS[algo].get(preset, {}))
    merged["env"] = dict(merged.get("env", {}))
    values = dict(values or {})
    if not isinstance(values.get("env", {}), dict):
        raise ConfigError("env must be a mapping of scenario keys to values")
    merged["env"].update(values.pop("env", {}))
    merged.update(values)
    merged["algo"], merged["preset"] = algo, preset
    return from_dict(TrainConfig, merged)

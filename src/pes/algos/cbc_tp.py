"""CBC-TP Net (paper §III-IV, Algorithm 1) and, with ``use_tp=False``, CBC Net.

One update (Algorithm 1, lines 11-21), from the shared replay storage:

1. TP Net: a minibatch of J history windows (n frames) and the evader's next k positions,
   loss eq. (7) (mean squared error in arena units);
2. critic: y_i = r_i + gamma * (1 - terminated) * Q'_i(s', a', p'), a' from the target actor on
   s' and the predicted path p' of s' (eqs. 5-6), masked mean over the pursuers alive in s;
   with ``charge_exits``, a pursuer leaving the game (disabled, or its episode failed) adds
   its last step's reward, crash term aside, times gamma / (1 - gamma). With ``n_step`` m > 1
   the target sums the rewards of up to m transitions of the episode and bootstraps from the
   last one's next state with gamma^m (:meth:`ReplayBuffer.n_step`);
3. actor: maximise Q_i(s, a_1..pi(o_i, p)..a_N, p) (eq. 4) for one random alive pursuer i of
   each sample, the others' actions from the buffer (``actor_gradient="one"``), or the mean
   Q_i with every alive pursuer acting (``"all"``), plus a small penalty on the squared
   pre-tanh action;
4. soft target updates with rate tau.

Gradients flow through the LSTMs by backpropagation through time (across the agents for the
actor and critic, across the history for TP Net). The prediction fed to the actor and critic is
TP Net's, detached: TP Net learns only from eq. (7), as Algorithm 1's hierarchy.

The predictions are stored with each transition as TP Net made them while acting (for s and
for s'), in the place of Algorithm 1's p_tar: recomputing them for every minibatch (two history
windows through TP Net per sample) is a large share of an update on a CPU, and TP Net converges
within the warm-up (its loss is ~1e-5 in arena units after a few hundred updates), so the
stored ones are current but for the first transitions. TP Net is trained from the warm-up on,
every ``tp_update_every`` updates; the actor and critic after the warm-up.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor, nn

from pes.algos.buffer import ReplayBuffer, transition, transition_fields
from pes.algos.common import masked_mean, optimise, soft_update, target_copy
from pes.algos.config import TrainConfig
from pes.algos.features import frames, pursuer_obs, relative_prediction
from pes.algos.nets import CBCActor, CBCCritic, TPNet
from pes.algos.noise import OUNoise
from pes.policies import SCRIPTED
from pes.sim.config import EnvConfig


class PursuerActors(nn.Module):
    """One :class:`CBCActor` shared by all pursuers, or one per pursuer."""

    def __init__(self, cfg: TrainConfig, num_pursuers: int) -> None:
        super().__init__()
        count = 1 if cfg.shared else num_pursuers
        pred_dim = 2 * cfg.horizon if cfg.use_tp else 0
        self.nets = nn.ModuleList(
            CBCActor(cfg.hidden, cfg.mlp_hidden, pred_dim, cfg.obstacle_scale, cfg.target_scale)
            for _ in range(count)
        )

    def pre_activation(self, obs: Tensor, mask: Tensor, pred: Tensor | None) -> Tensor:
        """obs (B, N, N, 8), mask (B, N, N), pred (B, N, 2k) or None -> (B, N, 2) before the
        tanh."""
        b, n = obs.shape[:2]
        if len(self.nets) == 1:
            p = pred.flatten(0, 1) if pred is not None else None
            out = self.nets[0].pre_activation(obs.flatten(0, 1), mask.flatten(0, 1), p)
            return out.view(b, n, 2)
        return torch.stack(
            [
                net.pre_activation(obs[:, i], mask[:, i], pred[:, i] if pred is not None else None)
                for i, net in enumerate(self.nets)
            ],
            dim=1,
        )

    def forward(self, obs: Tensor, mask: Tensor, pred: Tensor | None) -> Tensor:
        """obs (B, N, N, 8), mask (B, N, N), pred (B, N, 2k) or None -> actions (B, N, 2)."""
        return torch.tanh(self.pre_activation(obs, mask, pred))

    def pre_activation_one(
        self, obs: Tensor, mask: Tensor, pred: Tensor | None, agent: Tensor
    ) -> Tensor:
        """One pursuer per sample, before the tanh: obs (B, N, 8), mask (B, N), pred (B, 2k),
        agent (B,) long -> (B, 2)."""
        if len(self.nets) == 1:
            return self.nets[0].pre_activation(obs, mask, pred)
        out = obs.new_zeros(obs.shape[0], 2)
        for i, net in enumerate(self.nets):
            rows = agent == i
            if bool(rows.any()):
                p = pred[rows] if pred is not None else None
                out[rows] = net.pre_activation(obs[rows], mask[rows], p)
        return out


class PursuerCritics(nn.Module):
    """One :class:`CBCCritic` shared by all pursuers, or one per pursuer (pursuer i reads its Q
    from its own critic's cell i)."""

    def __init__(self, cfg: TrainConfig, num_pursuers: int) -> None:
        super().__init__()
        count = 1 if cfg.shared else num_pursuers
        pred_dim = 2 * cfg.horizon if cfg.use_tp else 0
        self.nets = nn.ModuleList(
            CBCCritic(cfg.hidden, cfg.mlp_hidden, pred_dim, cfg.obstacle_scale, cfg.target_scale)
            for _ in range(count)
        )

    def forward(self, state: Tensor, alive: Tensor, actions: Tensor, pred: Tensor | None):
        """-> Q (B, N)."""
        if len(self.nets) == 1:
            return self.nets[0](state, alive, actions, pred)
        return torch.stack(
            [net(state, alive, actions, pred)[:, i] for i, net in enumerate(self.nets)], dim=1
        )


class CBCTPPolicy(nn.Module):
    """The trained swarm as a :class:`pes.policies.Policy`: TP Net's prediction from
    ``info["history"]``, then the actor on each pursuer's observation."""

    def __init__(self, actor: PursuerActors, tp: TPNet | None) -> None:
        super().__init__()
        self.actor = actor
        self.tp = tp
        self.last_prediction: Tensor | None = None
        """(E, k, 2) the latest predicted evader positions in metres-free arena units."""

    def predict(self, info: dict[str, Tensor]) -> Tensor | None:
        """(E, k, 2) predicted normalised evader positions, or None without TP Net."""
        if self.tp is None:
            return None
        return self.tp(info["history"])

    @torch.no_grad()
    def __call__(self, obs: Tensor, info: dict[str, Tensor]) -> Tensor:
        return self.act(obs, info)

    def act(self, obs: Tensor, info: dict[str, Tensor]) -> Tensor:
        pred = self.predict(info)
        self.last_prediction = pred
        rel = None if pred is None else relative_prediction(pred, info["state"], obs.shape[1])
        return self.actor(obs, info["obs_mask"], rel)

    def reset(self, mask: Tensor | None = None) -> None:
        """Stateless between steps (the history comes from the environment)."""


def exit_charge(
    reward: Tensor,
    alive: Tensor,
    next_alive: Tensor,
    terminated: Tensor,
    gamma: float,
    capture_count: int,
    crash_reward: float,
) -> Tensor:
    """What a pursuer leaving the game still owes, added to its TD target (``charge_exits``).

    A pursuer alive in s leaves when it is not alive in s' (a crash under
    ``crash_mode="disable"``) or when the episode terminates with fewer than ``capture_count``
    pursuers alive (a failure). It is charged its last step's reward, the crash term aside, for
    every step to come: ``rate * gamma / (1 - gamma)``, as if it hovered where it left until the
    episode's end. Shapes: ``reward``, ``alive``, ``next_alive`` (B, N); ``terminated`` (B,);
    returns (B, N), zero for pursuers that stay.
    """
    lost = alive & ~next_alive
    failed = terminated & (next_alive.sum(-1) < capture_count)
    exits = lost | (alive & failed.unsqueeze(-1))
    rate = reward - crash_reward * lost.to(reward.dtype)
    return exits.to(reward.dtype) * rate * (gamma / (1.0 - gamma))


class TDWindows(NamedTuple):
    """A minibatch of B sampled transitions and their n-step windows (:meth:`CBCTP.sample_windows`):
    ``row``/``env`` index the transitions and ``last`` the row of each window's last one, all
    (B,); ``state`` (B, A, 8), ``alive`` (B, N) and ``action`` (B, N, 2) are the transitions';
    ``ret`` (B, N) the window's discounted reward sum; ``before_last`` (B, 1) gamma^(m-1) for a
    window of m transitions; ``next_state`` (B, A, 8), ``next_alive`` (B, N) and ``terminated``
    (B,) are the last transition's, which the TD target bootstraps from."""

    row: Tensor
    env: Tensor
    last: Tensor
    state: Tensor
    alive: Tensor
    action: Tensor
    ret: Tensor
    before_last: Tensor
    next_state: Tensor
    next_alive: Tensor
    terminated: Tensor


class CBCTP:
    """The CBC-TP Net learner (``use_tp=False``: CBC Net)."""

    name = "cbc-tp"

    def __init__(self, cfg: TrainConfig, env_cfg: EnvConfig, device: torch.device) -> None:
        self.cfg = cfg
        self.n = env_cfg.num_pursuers
        self.history = env_cfg.history_length
        self.capture_count, self.crash_reward = env_cfg.capture_count, env_cfg.crash_reward
        self.device = device
        self.actor = self.make_actor(cfg, self.n).to(device)
        self.critic = self.make_critic(cfg, self.n).to(device)
        self.tp = (
            TPNet(cfg.tp_hidden, cfg.tp_layers, cfg.horizon).to(device) if cfg.use_tp else None
        )
        self.actor_target = target_copy(self.actor)
        self.critic_target = target_copy(self.critic)
        # ``anchor_weight``: a frozen copy of the actor the run started from (``init_from``)
        self.anchor = target_copy(self.actor) if cfg.anchor_weight > 0 else None
        self.policy = CBCTPPolicy(self.actor, self.tp)
        self.target_policy = CBCTPPolicy(self.actor_target, self.tp)
        self.opt_actor = torch.optim.Adam(self.actor.parameters(), lr=cfg.lr_actor)
        self.opt_critic = torch.optim.Adam(self.critic.parameters(), lr=cfg.lr_critic)
        self.opt_tp = (
            torch.optim.Adam(self.tp.parameters(), lr=cfg.lr_tp) if self.tp is not None else None
        )
        fields = transition_fields(self.n)
        if cfg.use_tp:  # TP Net's predictions at s and s', inputs of the actor and the critic
            fields["pred"] = fields["next_pred"] = ((cfg.horizon, 2), torch.float32)
        self.demo = None
        if cfg.demo_policy:  # demonstrations, marked in the buffer for the actor's BC term
            self.demo = SCRIPTED[cfg.demo_policy](env_cfg)
            fields["demo"] = ((), torch.bool)
        self.buffer = ReplayBuffer(cfg.buffer_size, cfg.num_envs, fields, device)
        self.noise = OUNoise((cfg.num_envs, self.n, 2), cfg.noise_theta, 1.0, device=device)
        # (E, 1, 1) 1 for the environments that explore, 0 for the last greedy_envs share
        greedy = round(cfg.greedy_envs * cfg.num_envs)
        self.explore = (torch.arange(cfg.num_envs, device=device) < cfg.num_envs - greedy).float()
        self.explore = self.explore[:, None, None]
        self.updates = 0

    @staticmethod
    def adapt_env(env_cfg: EnvConfig) -> EnvConfig:
        """The training scenario (unchanged: the configured evader plays)."""
        return env_cfg

    # A baseline that trains like CBC-TP with other networks overrides these two (and
    # ``fixed_swarm``); see maddpg.py and bicnet.py.
    @staticmethod
    def make_actor(cfg: TrainConfig, num_pursuers: int) -> nn.Module:
        """The actor: ``(obs (B, N, N, 8), mask (B, N, N), pred (B, N, 2k) or None)`` ->
        actions (B, N, 2), with ``pre_activation`` (before the tanh) beside ``forward``."""
        return PursuerActors(cfg, num_pursuers)

    @staticmethod
    def make_critic(cfg: TrainConfig, num_pursuers: int) -> nn.Module:
        """The critic: ``(state (B, A, 8), alive (B, N), actions (B, N, 2), pred)`` -> Q (B, N)."""
        return PursuerCritics(cfg, num_pursuers)

    @staticmethod
    def fixed_swarm(cfg: TrainConfig) -> str | None:
        """Why a trained policy only serves the swarm size it was trained on (None if it
        serves any)."""
        return None if cfg.shared else "has one network per pursuer"

    # --- acting ----------------------------------------------------------------------------------
    @torch.no_grad()
    def act(self, obs: Tensor, info: dict[str, Tensor], noise_scale: float, gen):
        """(E, N, 2) actions of the current actor plus OU noise (none in the ``greedy_envs``
        share of the environments), clipped to [-1, 1], and no evader actions (the
        environment's evader plays)."""
        actions = self.policy.act(obs, info)  # also TP Net's prediction, stored by record()
        if self.demonstrating():  # the demonstrator plays as it would, without noise
            return self.demo(obs, info).clamp(-1.0, 1.0), None
        if noise_scale > 0:
            actions = actions + self.noise.sample(gen, noise_scale) * self.explore
        return actions.clamp(-1.0, 1.0), None

    def record(
        self,
        before: dict[str, Tensor],
        actions: Tensor,
        evader_actions: Tensor | None,
        reward: Tensor,
        terminated: Tensor,
        after: dict[str, Tensor],
    ) -> None:
        """Store one vector step: ``before``/``after`` are the infos around ``env.step``."""
        preds = {}
        if self.tp is not None:
            with torch.no_grad():
                preds = {
                    "pred": self.policy.last_prediction,
                    "next_pred": self.tp(after["final_history"]),
                }
        if self.demo is not None:
            preds["demo"] = torch.full_like(terminated, self.demonstrating())
        self.buffer.add(**transition(before, actions, reward, terminated, after), **preds)

    def demonstrating(self) -> bool:
        """Whether the demonstration policy plays the next step (``demo_transitions``)."""
        # The buffer's capacity is whole steps of all environments: it may fall a few
        # transitions short of buffer_size, and so of demo_transitions.
        wanted = min(self.cfg.demo_transitions, self.buffer.capacity)
        return self.demo is not None and len(self.buffer) < wanted

    def episode_reset(self, done: Tensor) -> None:
        self.noise.reset(done)
        if self.demo is not None:
            self.demo.reset(done)

    # --- learning --------------------------------------------------------------------------------
    def ready(self) -> bool:
        """Whether updates may start: TP Net as soon as a full window is stored."""
        wanted = max(self.cfg.tp_batch_size, 1) if self.tp is not None else self.cfg.warmup
        return len(self.buffer) >= max(wanted, self.cfg.batch_size) and (
            self.buffer.filled > self.history + self.cfg.horizon + 1
        )

    def sample_windows(self, gen: torch.Generator) -> TDWindows:
        """``batch_size`` sampled transitions, each with the n-step window (``n_step``) its
        TD target sums and bootstraps from (:meth:`ReplayBuffer.n_step`)."""
        cfg, buf = self.cfg, self.buffer
        row, env = buf.sample_index(cfg.batch_size, gen, future=cfg.n_step - 1)
        ret, last, length = buf.n_step(row, env, cfg.n_step, cfg.gamma)
        return TDWindows(
            row=row,
            env=env,
            last=last,
            state=buf.get("state", row, env),
            alive=buf.get("alive", row, env),
            action=buf.get("action", row, env),
            ret=ret,
            before_last=(cfg.gamma ** (length - 1).to(ret.dtype)).unsqueeze(-1),
            next_state=buf.get("next_state", last, env),
            next_alive=buf.get("next_alive", last, env),
            terminated=buf.get("terminated", last, env),
        )

    def update(self, gen: torch.Generator) -> dict[str, float]:
        """One gradient update of TP Net (every ``tp_update_every`` calls), then (after the
        warm-up) the critic and the actor; returns their metrics."""
        cfg, buf, n = self.cfg, self.buffer, self.n
        stats: dict[str, float] = {}
        if self.tp is not None and self.updates % cfg.tp_update_every == 0:
            stats.update(self.update_tp(gen))
        self.updates += 1
        if len(buf) < cfg.warmup:
            return stats

        w = self.sample_windows(gen)
        row, env, last = w.row, w.env, w.last
        state, alive, action = w.state, w.alive, w.action
        next_state, next_alive, terminated = w.next_state, w.next_alive, w.terminated
        pred = next_pred = None
        if self.tp is not None:
            pred, next_pred = buf.get("pred", row, env), buf.get("next_pred", last, env)
        with torch.no_grad():
            next_obs, next_mask = pursuer_obs(next_state, next_alive)
            rel = None if next_pred is None else relative_prediction(next_pred, next_state, n)
            next_action = self.actor_target(next_obs, next_mask, rel)
            q_next = self.critic_target(next_state, next_alive, next_action, next_pred)
            keep = (~terminated).unsqueeze(-1).float() * next_alive.float()
            y = w.ret + cfg.gamma * w.before_last * keep * q_next
            if cfg.charge_exits:  # exits happen only at a window's last transition
                y = y + w.before_last * exit_charge(
                    buf.get("reward", last, env),
                    alive,
                    next_alive,
                    terminated,
                    cfg.gamma,
                    self.capture_count,
                    self.crash_reward,
                )
        q = self.critic(state, alive, action, pred)
        critic_loss = masked_mean((q - y) ** 2, alive)
        stats["critic_grad"] = optimise(
            self.opt_critic, critic_loss, self.critic.parameters(), cfg.grad_clip
        )
        if self.critic_warming():
            return self.finish_update(None, critic_loss, q, alive, stats)

        # Actor (eq. 4). "one": in each sample one alive pursuer acts with the current actor and
        # the others keep their stored actions (MADDPG's per-agent gradient); "all": every alive
        # pursuer acts with it at once and the actor ascends the mean of their Qs (a centralised
        # policy gradient, as FACMAC's), N times the gradient samples for one critic pass.
        obs, mask = pursuer_obs(state, alive)
        rel = None if pred is None else relative_prediction(pred, state, n)
        if self.demonstrating() and cfg.bc_weight > 0:
            # While the demonstrator still plays, the critic is too young to follow: the actor
            # learns by behaviour cloning alone, every alive pursuer of every sample.
            pre = self.actor.pre_activation(obs, mask, rel)
            bc = masked_mean(((torch.tanh(pre) - action) ** 2).sum(-1), alive)
            reg = masked_mean((pre**2).sum(-1), alive)
            stats["bc_share"] = 1.0
            return self.finish_update(
                cfg.bc_weight * bc + cfg.action_reg * reg, critic_loss, q, alive, stats
            )
        if cfg.actor_gradient == "all":
            pre = self.actor.pre_activation(obs, mask, rel)  # (B, N, 2)
            new_action = torch.where(alive.unsqueeze(-1), torch.tanh(pre), action)
            acting = alive
            if self.anchor is not None:
                with torch.no_grad():
                    anchored = torch.tanh(self.anchor.pre_activation(obs, mask, rel))
                moved = ((torch.tanh(pre) - anchored) ** 2).sum(-1)  # (B, N)
        else:
            # the sampler's generator lives on the CPU (one RNG stream whatever the device)
            weights = alive.float().cpu() + 1e-6
            pick = torch.multinomial(weights, 1, generator=gen).squeeze(1).to(state.device)
            b = torch.arange(len(row), device=state.device)
            rel = None if rel is None else rel[b, pick]
            pre = self.actor.pre_activation_one(obs[b, pick], mask[b, pick], rel, pick)
            if self.anchor is not None:
                with torch.no_grad():
                    anchored = torch.tanh(
                        self.anchor.pre_activation_one(obs[b, pick], mask[b, pick], rel, pick)
                    )
                moved = ((torch.tanh(pre) - anchored) ** 2).sum(-1).unsqueeze(1)  # (B, 1)
            chosen = torch.nn.functional.one_hot(pick, n).bool() & alive
            new_action = torch.where(chosen.unsqueeze(-1), torch.tanh(pre).unsqueeze(1), action)
            pre = pre.unsqueeze(1) * chosen.unsqueeze(-1)
            acting = chosen
        for p in self.critic.parameters():
            p.requires_grad_(False)
        q_pi = self.critic(state, alive, new_action, pred)
        for p in self.critic.parameters():
            p.requires_grad_(True)
        # MADDPG's regulariser: the squared pre-activation, so that the tanh never saturates
        # (a penalty on the action itself vanishes there).
        reg = masked_mean((pre**2).sum(-1), acting)
        q_term, bc_term = masked_mean(q_pi, acting), 0.0
        if self.anchor is not None:
            # As TD3+BC's, with the starting actor's actions as the demonstrations: the Q term
            # over the batch's mean |Q|, plus the squared distance to the anchor's action.
            q_term = q_term / masked_mean(q_pi.detach().abs(), acting).clamp(min=1e-6)
            anchor_term = masked_mean(moved.expand_as(acting), acting)
            bc_term = cfg.anchor_weight * anchor_term
            stats["anchor_distance"] = float(anchor_term.detach())
        elif self.demo is not None and cfg.bc_weight > 0:
            # TD3+BC (Fujimoto & Gu 2021): the Q term divided by the batch's mean |Q|, so that
            # bc_weight weighs the same whatever the reward's scale, plus behaviour cloning on
            # the demonstrations (the other pursuers' actions are the stored ones, so they add
            # nothing).
            q_term = q_term / masked_mean(q_pi.detach().abs(), acting).clamp(min=1e-6)
            demo = buf.get("demo", row, env).unsqueeze(-1) & acting
            bc = ((new_action - action) ** 2).sum(-1)
            bc_term = cfg.bc_weight * (bc * demo).sum() / len(row)
            stats["bc_share"] = float(demo.sum()) / max(float(acting.sum()), 1.0)
        actor_loss = -q_term + cfg.action_reg * reg + bc_term
        return self.finish_update(actor_loss, critic_loss, q, alive, stats)

    def critic_warming(self) -> bool:
        """Whether this update is one of the first ``critic_warmup``: the critic learns alone
        (call after counting the update in ``self.updates``)."""
        return self.updates <= self.cfg.critic_warmup

    def finish_update(
        self, actor_loss: Tensor | None, critic_loss: Tensor, q: Tensor, alive: Tensor, stats: dict
    ) -> dict[str, float]:
        """The end of every actor-critic update (CBC-TP and its MADDPG / DDPG / BiCNet
        relatives): the actor's step (none with ``actor_loss=None``, the critic's warm-up), the
        soft target updates, the losses and the mean Q of the alive pursuers (q, alive: (B, N))
        added to ``stats``, which is returned."""
        cfg = self.cfg
        if actor_loss is not None:
            optimise(self.opt_actor, actor_loss, self.actor.parameters(), cfg.grad_clip)
            soft_update(self.actor_target, self.actor, cfg.tau)
            stats["actor_loss"] = float(actor_loss.detach())
        soft_update(self.critic_target, self.critic, cfg.tau)
        stats.update(
            critic_loss=float(critic_loss.detach()), q_mean=float(masked_mean(q.detach(), alive))
        )
        return stats

    def update_tp(self, gen: torch.Generator) -> dict[str, float]:
        """One supervised TP Net step (eq. 7) on J windows; FDE/ADE in arena units."""
        cfg, buf, k = self.cfg, self.buffer, self.cfg.horizon
        row, env = buf.sample_index(cfg.tp_batch_size, gen, past=self.history - 1, future=k)
        valid = buf.same_episode_ahead(row, env, k)
        hist = frames(buf.window("state", row, env, self.history))
        target = torch.stack(
            [buf.get("state", row, env, j)[:, -1, :2] for j in range(1, k + 1)], dim=1
        )
        pred = self.tp(hist)
        err = ((pred - target) ** 2).sum(-1)  # (B, k) squared distance
        loss = masked_mean(err.mean(-1), valid)
        optimise(self.opt_tp, loss, self.tp.parameters(), self.cfg.grad_clip)
        with torch.no_grad():
            dist = err.sqrt()
            fde = masked_mean(dist[:, -1], valid)
            ade = masked_mean(dist.mean(-1), valid)
        return {"tp_loss": float(loss.detach()), "tp_fde": float(fde), "tp_ade": float(ade)}

    @staticmethod
    def score(success_rate: float, episode_steps: float) -> float:
        """Training score of a log row (higher is better): success, then speed."""
        return success_rate - 1e-5 * episode_steps

    # --- saving ----------------------------------------------------------------------------------
    def modules(self) -> dict[str, nn.Module]:
        out = {
            "actor": self.actor,
            "critic": self.critic,
            "actor_target": self.actor_target,
            "critic_target": self.critic_target,
        }
        if self.tp is not None:
            out["tp"] = self.tp
        if self.anchor is not None:
            out["anchor"] = self.anchor
        return out

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        out = {"actor": self.opt_actor, "critic": self.opt_critic}
        if self.opt_tp is not None:
            out["tp"] = self.opt_tp
        return out

    def policy_modules(self) -> dict[str, nn.Module]:
        """What a deployed policy needs (shipped models hold only these)."""
        out = {"actor": self.actor}
        if self.tp is not None:
            out["tp"] = self.tp
        return out

    @classmethod
    def build_policy(cls, cfg: TrainConfig, env_cfg: EnvConfig, device) -> tuple[CBCTPPolicy, dict]:
        """An untrained policy of this architecture, and its modules by name (to load into)."""
        actor = cls.make_actor(cfg, env_cfg.num_pursuers).to(device)
        tp = TPNet(cfg.tp_hidden, cfg.tp_layers, cfg.horizon).to(device) if cfg.use_tp else None
        modules = {"actor": actor} | ({"tp": tp} if tp is not None else {})
        return CBCTPPolicy(actor, tp), modules

"""Temporal-difference targets of the replay learners, written once: n-step windows sampled
from a :class:`pes.learn.buffer.ReplayBuffer` of multi-agent transitions, and the target

    y_i = sum_{j<m} gamma^j r_{t+j,i} + gamma^m (1 - terminated) alive'_i V'_i
          + gamma^(m-1) exit_i

where m is the window's length (``n_step`` transitions at most, fewer where the episode ends or
a pursuer leaves), V'_i the learner's bootstrap value of the window's last next state and
exit_i what a pursuer leaving the game still owes (:func:`exit_charge`, the crash curriculum's
``charge_exits``).
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor

from pes.learn.buffer import ReplayBuffer


class TDWindows(NamedTuple):
    """A minibatch of B sampled transitions and their n-step windows (:func:`sample_windows`):
    ``row``/``env`` index the transitions and ``last`` the row of each window's last one, all
    (B,); ``state`` (B, A, 8), ``alive`` (B, N) and ``action`` (B, N, 2) are the transitions';
    ``ret`` (B, N) the window's discounted reward sum; ``before_last`` (B, 1) gamma^(m-1) for a
    window of m transitions; ``next_state`` (B, A, 8), ``next_alive`` (B, N), ``terminated``
    (B,) and ``last_reward`` (B, N) are the last transition's, which the target bootstraps
    from."""

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
    last_reward: Tensor


def sample_windows(
    buffer: ReplayBuffer, batch_size: int, n_step: int, gamma: float, gen: torch.Generator
) -> TDWindows:
    """``batch_size`` sampled transitions, each with the window of at most ``n_step``
    transitions its TD target sums and bootstraps from (:meth:`ReplayBuffer.n_step`)."""
    row, env = buffer.sample_index(batch_size, gen, future=n_step - 1)
    ret, last, length = buffer.n_step(row, env, n_step, gamma)
    return TDWindows(
        row=row,
        env=env,
        last=last,
        state=buffer.get("state", row, env),
        alive=buffer.get("alive", row, env),
        action=buffer.get("action", row, env),
        ret=ret,
        before_last=(gamma ** (length - 1).to(ret.dtype)).unsqueeze(-1),
        next_state=buffer.get("next_state", last, env),
        next_alive=buffer.get("next_alive", last, env),
        terminated=buffer.get("terminated", last, env),
        last_reward=buffer.get("reward", last, env),
    )


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


def td_target(
    w: TDWindows,
    value_next: Tensor,
    gamma: float,
    exits: tuple[int, float] | None = None,
) -> Tensor:
    """The n-step TD target (B, N) of the windows ``w`` with bootstrap values ``value_next``
    (B, N) of their last next states; ``exits = (capture_count, crash_reward)`` charges the
    pursuers that leave the game (:func:`exit_charge`; exits happen only at a window's last
    transition)."""
    keep = (~w.terminated).unsqueeze(-1).to(value_next.dtype) * w.next_alive.to(value_next.dtype)
    y = w.ret + gamma * w.before_last * keep * value_next
    if exits is not None:
        # a window ends where a pursuer leaves, so who is alive is the same at its first
        # transition as at its last
        y = y + w.before_last * exit_charge(
            w.last_reward, w.alive, w.next_alive, w.terminated, gamma, *exits
        )
    return y

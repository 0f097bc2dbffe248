"""How well does the CBC-TP actor imitate PID(PF) by behaviour cloning alone?

    python research/probes/bc_probe.py --speed 8 --transitions 150000 --rounds 8

Lets PID(PF) play ``--transitions`` transitions of the quick preset's 32 environments against
the default DDPG evader capped at ``--speed`` m/s (as ``demo_policy=pid-pf`` does; the recorded
result was measured when the default was the fully trained ``evader-ddpg``), then runs the
learner's updates with the actor on the behaviour-cloning term alone (as while a demonstrator
plays) and, every 2000 updates, evaluates the actor (100 episodes, disturbance, crashes
disable, at the same speed). Prints one JSON line per round. Results:
results/training/cbc_tp_demo_curriculum/bc_probe.log; the report:
research/demonstrations_and_curricula.md.
"""

from __future__ import annotations

import argparse
import json
import time

import torch
from pes.algos.config import build_train_config

import pes
from pes.algos.cbc_tp import CBCTP
from pes.evaluate import evaluate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speed", type=float, default=8.0, help="evader top speed (m/s)")
    parser.add_argument("--transitions", type=int, default=150_000)
    parser.add_argument("--rounds", type=int, default=8, help="rounds of 2000 updates")
    args = parser.parse_args()
    torch.set_num_threads(1)
    values = dict(
        demo_policy="pid-pf",
        demo_transitions=args.transitions,
        bc_weight=2.0,
        buffer_size=args.transitions,
        warmup=5000,
        env=dict(evader_max_speed=args.speed),
    )
    cfg = build_train_config("cbc-tp", "quick", values)
    env_cfg = cfg.env_config()
    learner = CBCTP(cfg, env_cfg, torch.device("cpu"))
    env = pes.make_env(env_cfg, num_envs=cfg.num_envs, seed=0, compile=True)
    gen = torch.Generator().manual_seed(0)
    obs, info = env.reset()
    learner.episode_reset(torch.ones(cfg.num_envs, dtype=torch.bool))
    start, captures, episodes = time.time(), 0, 0
    while learner.demonstrating():
        actions, _ = learner.act(obs, info, 0.0, gen)
        obs2, reward, terminated, truncated, info2 = env.step(actions)
        learner.record(info, actions, None, reward, terminated, info2)
        done = terminated | truncated
        if bool(done.any()):
            learner.episode_reset(done)
            captures += int(info2["success"][done].sum())
            episodes += int(done.sum())
        obs, info = obs2, info2
    print(
        f"collected {len(learner.buffer)} in {time.time() - start:.0f}s, "
        f"demo success {captures}/{episodes}",
        flush=True,
    )
    learner.demonstrating = lambda: True  # the BC-only actor update from here on
    eval_cfg = pes.EnvConfig().for_evaluation(evader_policy="ddpg", evader_max_speed=args.speed)
    start = time.time()
    for k in range(1, args.rounds + 1):
        for _ in range(2000):
            stats = learner.update(gen)
        result = evaluate(learner.policy, eval_cfg, episodes=100, num_envs=100, seed=1)
        row = dict(
            updates=k * 2000,
            s=round(time.time() - start),
            bc=stats.get("actor_loss"),
            success=result.success_rate,
            steps=result.mean_steps,
            crashes=result.mean_crashes,
        )
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()

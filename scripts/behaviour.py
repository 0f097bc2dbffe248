"""How a pursuer policy moves: speed, spread and distance to the evader over an episode.

    python scripts/behaviour.py cbc-tp pid-pf --episodes 100

Plays ``--episodes`` evaluation episodes (disturbance on, crashes disable, the shipped DDPG
evader) per policy and prints, for steps 0-99, 100-299 and 300-499 of the episodes still
running: the mean speed of the alive pursuers (m/s), their mean distance to the evader (m),
the distance of the nearest one (m) and the mean distance of the pursuers from their own
centroid (m, how spread out the swarm is); then, per policy, the crashes per episode and the
median step, distance to the evader (m) and speed just before (m/s) of the crashes; and, per
policy, where the evader is: the share of steps it is slower than 4 m/s or within 1.5 m of an
obstacle, the share of steps with at least 1 / 3 alive pursuers within 2 m and within 5 m of it,
and its median speed (m/s) and distance to its nearest obstacle (m) ``LOOKBACK`` steps before
each capture (a capture needs 3 pursuers within 2 m for 5 steps, so it is where the evader is
held up); and, per policy, where the time of a capture goes: the median step of the captured
episodes at which a pursuer first came within 2 m of the evader, three within 5 m, three within
2 m, and the capture itself, and the share of the steps between "three within 5 m" and "three
within 2 m" in which the evader was within 2 m of an obstacle. ``--evader-speed`` caps the
evader's speed (m/s; default: the scenario's 12).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from pes.cli import make_policy  # noqa: E402
from pes.sim.config import EnvConfig  # noqa: E402
from pes.sim.env import make_env  # noqa: E402

WINDOWS = ((0, 100), (100, 300), (300, 500))
LOOKBACK = 10  # steps before a capture at which the evader's speed and wall distance are read
SLOW = 4.0  # m/s, an evader slower than this is "slow"
NEAR_WALL = 1.5  # m, an evader closer than this to an obstacle is "at a wall"
CLOSING_WALL = 2.0  # m, the same for the steps in which three pursuers close from 5 m to 2 m


def measure(name: str, episodes: int, seed: int, evader_speed: float) -> dict[str, list[float]]:
    cfg = EnvConfig().for_evaluation(evader_policy="ddpg", evader_max_speed=evader_speed)
    env = make_env(cfg, num_envs=episodes, seed=seed)
    policy = make_policy(name, cfg, seed=seed)
    obs, info = env.reset(seed=seed)
    running = torch.ones(episodes, dtype=torch.bool)
    sums = {k: torch.zeros(len(WINDOWS)) for k in ("speed", "dist", "nearest", "spread")}
    counts = torch.zeros(len(WINDOWS))
    n = cfg.num_pursuers
    crashes = []  # (step, distance to the evader m, speed before m/s) of every crash
    speed = torch.zeros(episodes, n)
    # Evader rows per step: slow, at a wall, >= 1 / >= 3 pursuers within 2 m, within 5 m.
    evader_counts = torch.zeros(6)
    evader_steps = 0
    past = []  # the evader's (speed m/s, obstacle distance m) per step, (E,) each
    at_capture = []  # (speed, obstacle distance) LOOKBACK steps before each capture
    # First step (-1: not yet) with >= 1 pursuer within 2 m, >= 3 within 5 m, >= 3 within 2 m.
    first = torch.full((episodes, 3), -1, dtype=torch.long)
    closing = torch.zeros(episodes, 2)  # steps between 3 within 5 m and 3 within 2 m; at a wall
    phases = []  # per capture: the three first steps, the capture step, closing steps at a wall
    with torch.no_grad():
        for t in range(cfg.max_steps):
            obs, _, terminated, truncated, info = env.step(policy(obs, info))
            crashed = info["crashed"] & running[:, None]
            for e, j in crashed.nonzero().tolist():
                crashes.append((t, float(info["distances"][e, j]), float(speed[e, j])))
            state = info["final_state"]  # (E, N+1, 8), normalised
            alive = info["final_obs_mask"][:, :, 0] & running[:, None]
            w = next(i for i, (a, b) in enumerate(WINDOWS) if a <= t < b)
            pos = state[:, :n, :2] * cfg.arena_width
            speed = state[:, :n, 2:4].norm(dim=-1) * cfg.pursuer_max_speed
            dist = info["distances"]
            ev_speed = state[:, n, 2:4].norm(dim=-1) * cfg.pursuer_max_speed
            ev_wall = state[:, n, 4:6].norm(dim=-1) * cfg.arena_width
            past.append((ev_speed, ev_wall))
            near2 = ((dist < 2.0) & alive).sum(-1)
            near5 = ((dist < 5.0) & alive).sum(-1)
            flags = torch.stack(
                [
                    ev_speed < SLOW,
                    ev_wall < NEAR_WALL,
                    near2 >= 1,
                    near2 >= 3,
                    near5 >= 1,
                    near5 >= 3,
                ],
                dim=-1,
            )
            evader_counts += flags[running].float().sum(0)
            evader_steps += int(running.sum())
            then = past[max(0, t - LOOKBACK)]
            reached = torch.stack([near2 >= 1, near5 >= 3, near2 >= 3], dim=-1) & running[:, None]
            first = torch.where(reached & (first < 0), t, first)
            in_closing = running & (first[:, 1] >= 0) & (first[:, 2] < 0)
            closing[:, 0] += in_closing.float()
            closing[:, 1] += (in_closing & (ev_wall < CLOSING_WALL)).float()
            for e in (info["success"] & running).nonzero()[:, 0].tolist():
                at_capture.append((float(then[0][e]), float(then[1][e])))
                phases.append((*first[e].tolist(), t, *closing[e].tolist()))
            a = alive.float()
            k = a.sum(-1).clamp(min=1)
            centroid = (pos * a[..., None]).sum(1) / k[:, None]
            spread = ((pos - centroid[:, None]).norm(dim=-1) * a).sum(-1) / k
            rows = running & alive.any(-1)
            sums["speed"][w] += ((speed * a).sum(-1) / k)[rows].sum()
            sums["dist"][w] += ((dist * a).sum(-1) / k)[rows].sum()
            sums["nearest"][w] += dist.masked_fill(~alive, 1e9).min(-1).values[rows].sum()
            sums["spread"][w] += spread[rows].sum()
            counts[w] += rows.sum()
            running &= ~(terminated | truncated)
            if not running.any():
                break
    out = {k: (v / counts.clamp(min=1)).tolist() for k, v in sums.items()}
    table = torch.tensor(crashes).reshape(-1, 3)
    out["crashes"] = [len(crashes) / episodes, *table.median(0).values.tolist()] if crashes else []
    out["evader"] = (evader_counts / max(evader_steps, 1)).tolist()
    captured = torch.tensor(at_capture).reshape(-1, 2)
    out["captures"] = [len(at_capture), *captured.median(0).values.tolist()] if at_capture else [0]
    phase = torch.tensor(phases, dtype=torch.float).reshape(-1, 6)
    at_wall = phase[:, 5].sum() / phase[:, 4].sum().clamp(min=1)
    out["phases"] = [*phase[:, :4].median(0).values.tolist(), float(at_wall)] if phases else []
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policies", nargs="+")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--evader-speed", type=float, default=12.0)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print("| policy | steps | speed (m/s) | mean distance (m) | nearest (m) | spread (m) |")
    print("| --- | --- | --- | --- | --- | --- |")
    crash_rows, evader_rows, phase_rows = [], [], []
    for name in args.policies:
        stats = measure(name, args.episodes, args.seed, args.evader_speed)
        crash_rows.append((name, stats["crashes"]))
        evader_rows.append((name, stats["evader"], stats["captures"]))
        phase_rows.append((name, stats["phases"]))
        for i, (a, b) in enumerate(WINDOWS):
            print(
                f"| {name} | {a}-{b - 1} | {stats['speed'][i]:.1f} | {stats['dist'][i]:.1f} "
                f"| {stats['nearest'][i]:.1f} | {stats['spread'][i]:.1f} |",
                flush=True,
            )
    print()
    print("| policy | crashes / episode | median step | distance to the evader (m) | speed (m/s) |")
    print("| --- | --- | --- | --- | --- |")
    for name, row in crash_rows:
        cells = " | ".join(f"{x:.1f}" for x in row) if row else "0.0 | - | - | -"
        print(f"| {name} | {cells} |")
    print()
    print(
        f"| policy | evader < {SLOW:g} m/s | evader < {NEAR_WALL:g} m from an obstacle "
        "| >= 1 / >= 3 pursuers within 2 m | >= 1 / >= 3 within 5 m | captures "
        f"| evader speed (m/s) / obstacle distance (m) {LOOKBACK} steps before a capture |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for name, shares, captures in evader_rows:
        pct = [f"{100 * x:.1f} %" for x in shares]
        before = f"{captures[1]:.1f} / {captures[2]:.1f}" if captures[0] else "-"
        print(
            f"| {name} | {pct[0]} | {pct[1]} | {pct[2]} / {pct[3]} | {pct[4]} / {pct[5]} "
            f"| {captures[0]} | {before} |"
        )
    print()
    print(
        "| policy | first pursuer within 2 m | 3 within 5 m | 3 within 2 m | capture "
        f"| evader within {CLOSING_WALL:g} m of an obstacle while 3 close from 5 m to 2 m |"
    )
    print("| --- | --- | --- | --- | --- | --- |")
    for name, row in phase_rows:
        if row:
            steps = " | ".join(f"{x:.0f}" for x in row[:4])
            print(f"| {name} | {steps} | {100 * row[4]:.1f} % |")
        else:
            print(f"| {name} | - | - | - | - | - |")


if __name__ == "__main__":
    main()

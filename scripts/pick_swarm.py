"""Choose the pursuer policy of a run by evaluation on held-out episodes, not by training rows.

    pes train --algo cbc-tp ... --set snapshots=true --out runs/cbc_tp
    python scripts/pick_swarm.py runs/cbc_tp --out results/cbc_tp_pick.json

Training success (OU noise, no disturbance, crashed pursuers fly on) and the paper's
evaluation (disturbance on, crashes disable a pursuer) disagree, and the evaluated success of
a run swings between neighbouring policies (research/demonstrations_and_curricula.md). This
script picks a run's policy in two rounds, both with the paper's protocol against the shipped
DDPG evader (or ``--evader``) on the seed ``--seed``, which is held out: the model card and
``pes eval`` report seed 0, whose environments are seeded 0 ... num_envs - 1.

1. screen: every ``--every``-th snapshot of ``RUN/snapshots/`` (``snapshots=true`` keeps the
   policy of every log row), plus the run's ``policy.pt`` and any ``--extra`` policy file or
   checkpoint, over ``--screen`` episodes each;
2. confirm: the ``--top`` best of the screen over ``--episodes`` fresh episodes each (seed
   ``--seed + 1_000_000``); the best of these is chosen (ties: fewer steps).

"Best" is the higher success rate; with ``--max-steps S`` a policy whose mean episode steps are
S or more ranks after every one under S, whatever its success (the shipped swarm's target is
at least 95 % in under 200 steps: ``--max-steps 200``).

Every candidate's figures and the choice go to ``--out`` (JSON). Ship the choice with
``scripts/ship_model.py``, whose model card evaluates it again on seed 0.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from pes.algos.loading import load_pursuer_policy  # noqa: E402
from pes.evaluate import evaluate  # noqa: E402
from pes.sim.config import EnvConfig  # noqa: E402

CONFIRM_SEED_OFFSET = 1_000_000
"""The confirm round's episodes start this far after the screen's (no environment seed shared)."""


def candidates(run: Path, every: int, extra: list[str]) -> list[tuple[str, int | None]]:
    """(path, training episode or None) of every policy to screen, in training order."""
    snaps = sorted((run / "snapshots").glob("ep*.pt"), key=lambda p: int(p.stem[2:]))
    out: list[tuple[str, int | None]] = [(str(p), int(p.stem[2:])) for p in snaps[::every]]
    if snaps and (len(snaps) - 1) % every:
        out.append((str(snaps[-1]), int(snaps[-1].stem[2:])))  # always the last snapshot
    if (run / "policy.pt").exists():
        out.append((str(run / "policy.pt"), None))
    out += [(e, None) for e in extra]
    return out


def measure(path: str, cfg: EnvConfig, episodes: int, num_envs: int, seed: int) -> dict:
    """The paper-protocol figures of one policy (``EvalResult.summary()`` plus timing)."""
    policy, _ = load_pursuer_policy(path, cfg)
    start = time.time()
    result = evaluate(policy, cfg, episodes=episodes, num_envs=num_envs, seed=seed)
    return {**result.summary(), "seconds": round(time.time() - start, 1)}


def ranked(rows: list[dict], key: str, max_steps: float = math.inf) -> list[dict]:
    """``rows`` best first by their ``key`` round ("screen" or "confirm"): those under
    ``max_steps`` mean steps first, then the higher success rate, then fewer steps."""

    def order(row: dict) -> tuple[bool, float, float]:
        r = row[key]
        return (r["mean_steps"] >= max_steps, -r["success_rate"], r["mean_steps"])

    return sorted(rows, key=order)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="a pursuer run folder (best with snapshots=true)")
    parser.add_argument("--out", type=Path, required=True, help="JSON file of every candidate")
    parser.add_argument("--every", type=int, default=1, help="screen every k-th snapshot")
    parser.add_argument("--screen", type=int, default=250, help="episodes per screened policy")
    parser.add_argument("--top", type=int, default=3, help="policies confirmed")
    parser.add_argument("--episodes", type=int, default=1000, help="episodes per confirmed one")
    parser.add_argument("--num-envs", type=int, default=250)
    parser.add_argument("--seed", type=int, default=10_000, help="held out: not 0")
    parser.add_argument("--evader", default="ddpg", help="evader policy (default: shipped DDPG)")
    parser.add_argument("--extra", nargs="*", default=[], help="more policy files / checkpoints")
    parser.add_argument("--threads", type=int, default=0, help="torch threads (0 = default)")
    parser.add_argument(
        "--max-steps",
        type=float,
        default=math.inf,
        help="rank policies with this many mean steps or more after the others",
    )
    args = parser.parse_args()
    if args.every < 1 or args.screen < 1 or args.top < 1 or args.episodes < 1:
        sys.exit("error: --every, --screen, --top and --episodes must be at least 1")
    if args.seed == 0:
        sys.exit("error: --seed 0 is the reporting seed; pick on another one")
    if args.threads:
        torch.set_num_threads(args.threads)

    todo = candidates(args.run, args.every, args.extra)
    if not todo:
        sys.exit(f"error: no snapshots or policy.pt in '{args.run}' and no --extra")
    cfg = EnvConfig().for_evaluation(evader_policy=args.evader)
    print(f"screening {len(todo)} policies over {args.screen} episodes each", flush=True)
    rows = []
    for path, episode in todo:
        row = {"policy": path, "episode": episode}
        row["screen"] = measure(path, cfg, args.screen, args.num_envs, args.seed)
        rows.append(row)
        s = row["screen"]
        print(
            f"{path}: {100 * s['success_rate']:.1f} % ± {100 * s['success_rate_ci95']:.1f}, "
            f"{s['mean_steps']:.0f} steps, {s['mean_crashes']:.2f} crashes",
            flush=True,
        )

    finalists = ranked(rows, "screen", args.max_steps)[: args.top]
    print(f"confirming {len(finalists)} over {args.episodes} fresh episodes each", flush=True)
    for row in finalists:
        seed = args.seed + CONFIRM_SEED_OFFSET
        row["confirm"] = measure(row["policy"], cfg, args.episodes, args.num_envs, seed)
        c = row["confirm"]
        print(
            f"{row['policy']}: {100 * c['success_rate']:.1f} % ± "
            f"{100 * c['success_rate_ci95']:.1f}, {c['mean_steps']:.0f} steps",
            flush=True,
        )
    chosen = ranked(finalists, "confirm", args.max_steps)[0]
    report = {
        "protocol": {
            "evader": args.evader,
            "disturbance": True,
            "crash_mode": "disable",
            "screen": {"episodes": args.screen, "seed": args.seed},
            "confirm": {"episodes": args.episodes, "seed": args.seed + CONFIRM_SEED_OFFSET},
            "num_envs": args.num_envs,
            "max_steps": args.max_steps if math.isfinite(args.max_steps) else None,
        },
        "command": " ".join(["python", "scripts/pick_swarm.py", *sys.argv[1:]]),
        "chosen": chosen["policy"],
        "candidates": rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2) + "\n")
    c = chosen["confirm"]
    print(f"chosen: {chosen['policy']} ({100 * c['success_rate']:.1f} % on the confirm round)")


if __name__ == "__main__":
    main()

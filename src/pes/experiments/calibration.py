"""Calibration of the default scenario: how hard is the game without learning?

    python -m pes.experiments.calibration --episodes 1000 --out results/calibration.json

Measures, with the paper's evaluation settings (disturbance on, ``crash_mode="disable"``),
on the default map, against the scripted ``flee`` evader:

* five PID(PF) pursuers (capture: 3 within 2 m for 5 steps) -- the paper reports 27.3 % for
  PID(PF) against its DDPG evader;
* one PID(PF) pursuer (capture: 1 within 2 m for 5 steps) -- a lone pursuer should essentially
  never catch the faster evader;
* five random pursuers, for scale;

and five PID(PF) pursuers against the shipped DDPG evaders (those this installation has):

* the default one, calibrated to the paper's (``evader-ddpg-paper``): PID(PF) should catch it
  about as often as the paper's 27.3 %;
* the fully trained one (``evader-ddpg``) with its top speed capped at 8 ... 12 m/s (12: the
  scenario's default; the pursuers fly at 10): how much of its strength is its speed.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch

from pes.evaluate import evaluate
from pes.models import is_shipped
from pes.policies import PIDPotentialField, RandomPolicy
from pes.sim.bench import machine_info
from pes.sim.config import EnvConfig

CASES = {
    "pid-pf, 5 pursuers": (PIDPotentialField, {"num_pursuers": 5, "capture_count": 3}),
    "pid-pf, 1 pursuer": (PIDPotentialField, {"num_pursuers": 1, "capture_count": 1}),
    "random, 5 pursuers": (RandomPolicy, {"num_pursuers": 5, "capture_count": 3}),
}
"""Name -> (pursuer policy, scenario overrides), against ``flee``."""

EVADER_SPEEDS = (8.0, 9.0, 10.0, 11.0, 12.0)
"""Top speeds (m/s) of the fully trained DDPG evader against five PID(PF) pursuers."""

PAPER_EVADER_CASE = "pid-pf, 5 pursuers, DDPG evader calibrated to the paper's"
"""The case "five PID(PF) pursuers against the default evader, ``evader-ddpg-paper``"."""


def evader_speed_case(speed: float) -> str:
    """The name of the case "five PID(PF) pursuers against the fully trained evader
    (``evader-ddpg``) capped at ``speed`` m/s" (a key of ``results/calibration.json``)."""
    return f"pid-pf, 5 pursuers, DDPG evader at {speed:g} m/s"


def cases() -> dict[str, tuple[type, dict]]:
    """Every case measured: :data:`CASES`, then the default DDPG evader, then the fully trained
    one at :data:`EVADER_SPEEDS` (those of the shipped evaders this installation has)."""
    out = dict(CASES)
    if is_shipped("evader-ddpg-paper"):
        out[PAPER_EVADER_CASE] = (
            PIDPotentialField,
            {"evader_policy": "ddpg", "evader_model": "evader-ddpg-paper"},
        )
    if is_shipped("evader-ddpg"):
        for v in EVADER_SPEEDS:
            out[evader_speed_case(v)] = (
                PIDPotentialField,
                {"evader_policy": "ddpg", "evader_model": "evader-ddpg", "evader_max_speed": v},
            )
    return out


def run(episodes: int, seed: int) -> dict:
    rows = {}
    for name, (policy_cls, overrides) in cases().items():
        config = EnvConfig().for_evaluation(**overrides)
        start = time.time()
        result = evaluate(
            policy_cls(config),
            config,
            episodes=episodes,
            num_envs=min(episodes, 250),
            seed=seed,
            progress=True,
        )
        rows[name] = {**result.summary(), "seconds": round(time.time() - start, 1)}
        print(
            f"{name}: success {100 * result.success_rate:.1f} % "
            f"(± {100 * result.success_rate_ci95:.1f}), steps {result.mean_steps:.0f}, "
            f"crashes/episode {result.mean_crashes:.2f}",
            file=sys.stderr,
        )
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="results/calibration.json")
    args = parser.parse_args()
    torch.set_num_threads(max(1, torch.get_num_threads()))
    report = {
        "command": "python -m pes.experiments.calibration " + " ".join(sys.argv[1:]),
        "date": time.strftime("%Y-%m-%d"),
        "machine": machine_info(),
        "settings": "default map, flee evader unless named, disturbance on, crash_mode=disable",
        "results": run(args.episodes, args.seed),
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2))
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())

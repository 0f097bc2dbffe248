"""Evaluation speed: ``pes eval`` of the shipped swarm, alone and beside a CPU-bound process.

    python benchmarks/bench_eval.py                 # writes benchmarks/results/eval_cpu.json
    python benchmarks/bench_eval.py --episodes 200 --threads 1 --out /tmp/eval.json
    python benchmarks/bench_eval.py --episodes 0 --out benchmarks/results/first_step_cpu.json

What is measured, each as a fresh ``pes eval`` process, exactly as a user runs it:

* ``pes eval --policy cbc-tp --episodes N --disturbance --json --threads T`` for every T of
  ``--threads``: its wall time and its figures (success rate, mean steps), which must not depend
  on T or on what runs beside it;
* the same beside a second CPU-bound process (a Python busy loop), the contention a user meets
  when two jobs share the machine;
* the time from ``import pes`` to the first step of ``pes.make_env()`` in a fresh process with an
  empty kernel cache (``NUMBA_CACHE_DIR`` pointed at a new folder), as on a new machine, and
  again with the cache that first run left; and, stepping on, when the kernels compiled in the
  background begin to serve.

The load average before each run is recorded: other work on the machine slows every figure.
Progress goes to stderr; the JSON object to stdout and to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

FIRST_STEP = """
import json, time
t = time.perf_counter()
import pes, torch
from pes.sim import kernels
env = pes.make_env()
env.reset(seed=0)
action = torch.zeros(1, env.num_pursuers, 2)
env.step(action)
first, compiled, steps = time.perf_counter() - t, kernels.serving(), 1
deadline = time.monotonic() + 600
cpu = torch.device("cpu")
while not kernels.usable(cpu) and not kernels._failed and time.monotonic() < deadline:
    env.step(action)  # in torch, while the kernels compile in the background
    steps += 1
print(json.dumps({"first_step_s": round(first, 2), "kernels_at_first_step": compiled,
                  "kernels_after_s": round(time.perf_counter() - t, 2), "steps_before": steps}))
"""


def log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def run_eval(episodes: int, threads: int) -> dict:
    """One ``pes eval`` process: its JSON figures and wall time (s)."""
    command = [
        "pes", "eval", "--policy", "cbc-tp", "--episodes", str(episodes), "--disturbance",
        "--json", "--threads", str(threads),
    ]  # fmt: skip
    load = os.getloadavg()[0]
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, check=True)
    wall = time.perf_counter() - start
    result = json.loads(done.stdout)
    return {
        "threads": threads,
        "wall_s": round(wall, 1),
        "load_before": round(load, 2),
        "success_rate": result["success_rate"],
        "mean_steps": result["mean_steps"],
        "command": " ".join(command),
    }


def first_step(cache_dir: str) -> dict:
    """A fresh process from ``import pes``: seconds to its first step, whether that step ran the
    kernels, seconds until they serve (compiled aside while the steps run the torch code) and
    the steps taken until then."""
    env = {**os.environ, "NUMBA_CACHE_DIR": cache_dir}
    done = subprocess.run(
        [sys.executable, "-c", FIRST_STEP], capture_output=True, text=True, check=True, env=env
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=1000, help="0: the first step only")
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--out", default="benchmarks/results/eval_cpu.json")
    args = parser.parse_args()

    import torch

    from pes.sim.bench import machine_info

    report: dict = {
        "benchmark": "pes eval of the shipped swarm, alone and beside one CPU-bound process"
        if args.episodes > 0
        else "import pes to the first step of pes.make_env(), on an empty and a warm kernel cache",
        "command": "python benchmarks/bench_eval.py " + " ".join(sys.argv[1:]),
        "date": time.strftime("%Y-%m-%d"),
        "machine": {**machine_info("cpu"), "torch_threads": torch.get_num_threads()},
        "episodes": args.episodes,
        "runs": [],
    }
    with tempfile.TemporaryDirectory() as cache:
        log("first step, empty kernel cache ...")
        report["first_step_s"] = {"load_before": round(os.getloadavg()[0], 2)}
        report["first_step_s"]["empty_cache"] = first_step(cache)
        report["first_step_s"]["cached"] = first_step(cache)
    for beside in (False, True) if args.episodes > 0 else ():
        busy = None
        if beside:
            busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
        try:
            for threads in args.threads:
                where = "beside a busy process" if beside else "alone"
                log(f"pes eval, {args.episodes} episodes, {threads} thread(s), {where} ...")
                row = run_eval(args.episodes, threads)
                row["beside_busy_process"] = beside
                report["runs"].append(row)
                log(f"  {row['wall_s']} s: {100 * row['success_rate']:.1f} % in "
                    f"{row['mean_steps']} steps")  # fmt: skip
        finally:
            if busy is not None:
                busy.kill()
    figures = {(r["success_rate"], r["mean_steps"]) for r in report["runs"]}
    report["same_figures_in_every_run"] = len(figures) == 1 if report["runs"] else None
    text = json.dumps(report, indent=2)
    print(text)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

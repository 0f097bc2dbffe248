"""Fly an exported swarm policy in the simulator: onnxruntime and numpy choose the actions.

    pes export-onnx cbc-tp cbc_tp.onnx
    python examples/onnx_policy.py cbc_tp.onnx --episodes 4 --num-pursuers 6

The policy side uses only the ONNX file, onnxruntime and numpy -- what a vehicle's computer
would run. torch appears only inside the simulator (``pes.make_env``), whose tensors are turned
into numpy arrays with ``.numpy()``; ``env.step`` takes the numpy actions as they are. The
graph's inputs and outputs are documented in docs/export.md.
"""

from __future__ import annotations

import argparse

import numpy as np
import onnxruntime as ort

import pes


def policy_inputs(session: ort.InferenceSession, obs, info) -> dict[str, np.ndarray]:
    """The graph's inputs from the simulator's observation and info, as numpy arrays."""
    inputs = {
        "obs": obs.numpy(),  # (E, N, N, 8) float32
        # Who is alive in the state the policy acts in (after an auto-reset, the new episode's).
        "alive": info["obs_mask"][:, :, 0].numpy(),  # (E, N) bool
        "history": info["history"].numpy(),  # (E, n, N + 1, 4) float32; unused by CBC graphs
    }
    wanted = {i.name for i in session.get_inputs()}
    return {k: v for k, v in inputs.items() if k in wanted}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("onnx", help="a file written by `pes export-onnx`")
    parser.add_argument("--episodes", type=int, default=2, help="episodes, played side by side")
    parser.add_argument("--num-pursuers", type=int, default=5, help="swarm size (any N >= 1)")
    parser.add_argument("--max-steps", type=int, default=500, help="episode limit")
    parser.add_argument("--damaged", type=int, default=0, help="pursuers disabled at the start")
    parser.add_argument("--evader", default="flee", help="evader policy: flee or ddpg")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    config = pes.EnvConfig(
        num_pursuers=args.num_pursuers,
        max_steps=args.max_steps,
        damaged=args.damaged,
        evader_policy=args.evader,
        disturbance=True,
        crash_mode="disable",
    )
    env = pes.make_env(config, num_envs=args.episodes, seed=args.seed)
    session = ort.InferenceSession(args.onnx, providers=["CPUExecutionProvider"])
    outputs = [o.name for o in session.get_outputs()]

    obs, info = env.reset(seed=args.seed)
    results: list[dict | None] = [None] * args.episodes
    while any(r is None for r in results):
        out = dict(zip(outputs, session.run(None, policy_inputs(session, obs, info))))
        actions = out["actions"]  # (E, N, 2) in [-1, 1]
        obs, _, terminated, truncated, info = env.step(actions)  # numpy is accepted
        done = (terminated | truncated).numpy()
        for e in np.flatnonzero(done):
            if results[e] is None:
                results[e] = {
                    "success": bool(info["success"][e]),
                    "steps": int(info["steps"][e]),
                    "crashes": int(info["crashes"][e]),
                }
    for e, r in enumerate(results):
        verdict = "captured the evader" if r["success"] else "did not capture the evader"
        print(
            f"episode {e} (seed {args.seed + e}): {args.num_pursuers} pursuers {verdict} in "
            f"{r['steps']} steps ({r['steps'] * config.dt:.1f} s), {r['crashes']} crashes"
        )
    wins = sum(r["success"] for r in results)
    mean_steps = np.mean([r["steps"] for r in results])
    print(f"success {wins}/{args.episodes}, mean steps {mean_steps:.1f}")


if __name__ == "__main__":
    main()

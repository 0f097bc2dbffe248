"""What else could make an update cheaper on this CPU, measured: the recurrent kernel and the
precision.

    python benchmarks/bench_update_options.py --threads 1 \
        --out benchmarks/results/update_options_cpu.json

* ``lstm``: the bidirectional LSTM the CBC-TP Net and BiCNet updates are made of, at the
  quick presets' sizes (CBC-TP Net's target actor over every pursuer's observation, its actor
  and critic over a minibatch, BiCNet's 128 units), as torch's ``nn.LSTM`` (oneDNN's kernel on a
  CPU) and as the same cell written out and compiled by ``torch.compile`` (Inductor fuses the
  gate arithmetic, the matrix products stay library calls): milliseconds forward (no
  gradient) and forward plus backward;
* ``autocast``: one update of each learner's quick preset in float32 and under
  ``torch.autocast("cpu", dtype=torch.bfloat16)`` (matrix products and LSTMs in bfloat16):
  milliseconds, the median of ``--updates`` updates after warm-up. Bfloat16 changes the
  update's arithmetic, so a faster time is not the same learning.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import torch
from bench_train import learner_and_env  # beside this file
from torch import Tensor, nn

from pes.sim.bench import machine_info

LSTM_SIZES = [  # (hidden, batch, sequence, inputs, what)
    (32, 2560, 6, 9, "CBC-TP Net's target actor: 512 samples x 5 pursuers"),
    (32, 512, 6, 9, "CBC-TP Net's actor: 512 samples"),
    (32, 512, 5, 23, "CBC-TP Net's critic: 512 samples"),
    (128, 256, 5, 17, "BiCNet's critic: 256 samples"),
]


def written_out(x: Tensor, w_ih: Tensor, w_hh: Tensor, b: Tensor) -> Tensor:
    """A bidirectional LSTM written out: x (B, T, I), w_ih (2, 4H, I), w_hh (2, 4H, H), b
    (2, 4H) -> (B, T, 2H), as ``nn.LSTM(batch_first=True, bidirectional=True)``."""
    steps, hidden = x.shape[1], w_hh.shape[-1]
    gates_x = torch.einsum("bti,dgi->dtbg", x, w_ih) + b[:, None, None, :]
    h = x.new_zeros(2, x.shape[0], hidden)
    c = torch.zeros_like(h)
    forward, backward = [], []
    for t in range(steps):
        g = torch.stack([gates_x[0, t], gates_x[1, steps - 1 - t]]) + torch.bmm(
            h, w_hh.transpose(1, 2)
        )
        i, f, cell, o = g.chunk(4, -1)
        c = torch.sigmoid(f) * c + torch.sigmoid(i) * torch.tanh(cell)
        h = torch.sigmoid(o) * torch.tanh(c)
        forward.append(h[0])
        backward.append(h[1])
    return torch.cat([torch.stack(forward, 1), torch.stack(backward[::-1], 1)], -1)


def timed(fn, repeats: int = 20) -> float:
    """Milliseconds per call of ``fn``, the median of ``repeats`` after three warm-ups."""
    for _ in range(3):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return round(statistics.median(times) * 1000, 2)


def lstm_row(compiled, hidden: int, batch: int, steps: int, inputs: int, what: str) -> dict:
    """oneDNN's ``nn.LSTM`` against the compiled written-out cell at one size."""
    lstm = nn.LSTM(inputs, hidden, batch_first=True, bidirectional=True)
    weights = [
        torch.stack([getattr(lstm, f"{name}_l0"), getattr(lstm, f"{name}_l0_reverse")])
        for name in ("weight_ih", "weight_hh")
    ]
    bias = torch.stack(
        [lstm.bias_ih_l0 + lstm.bias_hh_l0, lstm.bias_ih_l0_reverse + lstm.bias_hh_l0_reverse]
    )
    w_ih, w_hh, b = (t.detach().requires_grad_() for t in (*weights, bias))
    x = torch.randn(batch, steps, inputs)
    grad_x = x.clone().requires_grad_()
    same = (lstm(x)[0] - written_out(x, w_ih, w_hh, b)).abs().max().item()

    def onednn_forward():
        with torch.no_grad():
            lstm(x)

    def onednn_backward():
        lstm(grad_x)[0].sum().backward()

    def compiled_forward():
        with torch.no_grad():
            compiled(x, w_ih, w_hh, b)

    def compiled_backward():
        compiled(grad_x, w_ih, w_hh, b).sum().backward()

    row = {
        "what": what,
        "hidden": hidden,
        "batch": batch,
        "steps": steps,
        "max_abs_difference": same,
        "onednn_forward_ms": timed(onednn_forward),
        "compiled_forward_ms": timed(compiled_forward),
        "onednn_forward_backward_ms": timed(onednn_backward),
        "compiled_forward_backward_ms": timed(compiled_backward),
    }
    print(json.dumps(row), flush=True)
    return row


def lstm_rows() -> list[dict]:
    torch._dynamo.config.recompile_limit = 64  # a graph per size, with and without gradients
    compiled = torch.compile(written_out, dynamic=False)
    return [lstm_row(compiled, *size) for size in LSTM_SIZES]


def autocast_row(algo: str, updates: int) -> dict:
    """One learner's quick-preset update in float32 and under bfloat16 autocast."""
    cfg, cls, _, learner, env, gen = learner_and_env(algo, "quick", "cpu", compile_env=False)
    obs, info = env.reset()
    lc = cfg.learner
    need = lc.batch_size if cls.on_policy else max(lc.warmup, lc.batch_size)

    def step() -> None:
        nonlocal obs, info
        actions, evader = learner.act(obs, info, 0.2, gen)
        obs2, reward, terminated, _, info2 = env.step(actions, evader)
        learner.record(info, actions, evader, reward, terminated, info2)
        obs, info = obs2, info2

    while not learner.ready() or (not cls.on_policy and len(learner.buffer) < need):
        step()

    def update(bf16: bool) -> float:
        while not learner.ready():
            step()
        start = time.perf_counter()
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            learner.update(gen)
        return time.perf_counter() - start

    times: dict[bool, list[float]] = {False: [], True: []}
    for bf16 in (False, True):
        update(bf16)  # warm-up
    for _ in range(updates):  # in turn, so that both see the same load
        for bf16 in (False, True):
            times[bf16].append(update(bf16))
    fp32, bf16 = (round(statistics.median(times[k]) * 1000, 2) for k in (False, True))
    row = {"algo": algo, "float32_update_ms": fp32, "bfloat16_update_ms": bf16}
    row["speedup"] = round(fp32 / bf16, 3)
    print(json.dumps(row), flush=True)
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--algos", nargs="+", default=["cbc-tp", "bicnet", "maddpg", "ppo"])
    parser.add_argument("--updates", type=int, default=10)
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--out", default="benchmarks/results/update_options_cpu.json")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    result = {
        "machine": machine_info("cpu"),
        "command": f"python benchmarks/bench_update_options.py --threads {args.threads} "
        f"--algos {' '.join(args.algos)} --updates {args.updates}",
        "lstm": lstm_rows(),
        "autocast": [autocast_row(algo, args.updates) for algo in args.algos],
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()

"""A trained CBC-TP (or CBC) swarm as one ONNX graph, toward real vehicles (docs/export.md).

The graph holds TP Net and the actor: from every pursuer's Table I observation, the alive mask
and the history window it returns every pursuer's desired acceleration, for any number of
pursuers and any batch (both axes are dynamic). It is exactly :class:`pes.algos.cbc_tp.
CBCTPPolicy` (the actions of pursuers that are not alive set to 0), so that
``onnxruntime`` gives the actions PyTorch gives; docs/export.md documents the inputs and
outputs.

Inputs (float32 unless said; positions divided by the arena size, velocities by the pursuer's
max speed, as in the observations of :mod:`pes.sim.scenario`):

* ``obs`` (batch, N, N, 8): the environment's ``obs``; row 0 of pursuer i is itself.
* ``alive`` (batch, N) bool: ``info["alive"]``; rows of dead pursuers are zeroed in the graph.
* ``history`` (batch, n, N + 1, 4), CBC-TP only: ``info["history"]``, the last n frames of
  [position, velocity] of every vehicle (pursuers, then the evader), oldest first.

Outputs: ``actions`` (batch, N, 2) in [-1, 1] (fractions of the pursuer's max acceleration), and
for CBC-TP ``prediction`` (batch, k, 2), TP Net's next k evader positions (arena units).
"""

from __future__ import annotations

import contextlib
import io
import logging
import warnings
from pathlib import Path
from typing import Any

import torch
from torch import Tensor, nn

from pes.algos.cbc_tp import PursuerActors, TPNet
from pes.algos.loading import describe, load_pursuer_policy
from pes.errors import CheckpointError, PESError
from pes.learn.actor_critic import DeterministicPolicy
from pes.sim.config import EnvConfig

EXPORTABLE = ("cbc-tp", "cbc")
"""The algorithms whose policies ``export_onnx`` takes."""
INSTALL_HINT = "ONNX export needs the 'onnx' extra: pip install 'pes[onnx]'"


def other_rows(num_pursuers: Tensor | int, device: torch.device | str = "cpu") -> Tensor:
    """(N, N) long: row k of pursuer i's observation shows pursuer ``rows[i, k]`` (itself, then
    the others in increasing order), as :func:`pes.learn.features.other_index`, but built with
    tensor operations so that N stays symbolic in an exported graph."""
    ar = torch.arange(num_pursuers, device=device)
    i, k = ar[:, None], ar[None, :]
    return torch.where(k == 0, i, k - (k <= i).long())


class ExportablePolicy(nn.Module):
    """The function the ONNX graph computes: ``forward(obs, alive[, history])``.

    Args:
        actor: the pursuers' actor(s) of a CBC-TP / CBC policy.
        tp: its TP Net, or None (CBC).
    """

    def __init__(self, actor: PursuerActors, tp: TPNet | None) -> None:
        super().__init__()
        self.actor = actor
        self.tp = tp

    def forward(
        self, obs: Tensor, alive: Tensor, history: Tensor | None = None
    ) -> Tensor | tuple[Tensor, Tensor]:
        """obs (B, N, N, 8), alive (B, N) bool, history (B, n, N+1, 4) -> actions (B, N, 2) (and,
        with TP Net, the prediction (B, k, 2))."""
        rows = other_rows(obs.shape[1], obs.device)
        mask = alive[:, rows] & alive.unsqueeze(-1)  # = info["obs_mask"]
        obs = obs * mask.unsqueeze(-1).to(obs.dtype)
        if self.tp is None:
            return self.actor(obs, mask, None) * alive.unsqueeze(-1).to(obs.dtype)
        pred = self.tp(history)
        # Each pursuer's own position is its first row (= info["state"][:, :N, :2]).
        rel = (pred.unsqueeze(1) - obs[:, :, 0, :2].unsqueeze(2)).flatten(2)
        actions = self.actor(obs, mask, rel) * alive.unsqueeze(-1).to(obs.dtype)
        return actions, pred


def load_exportable(spec: str | Path) -> tuple[ExportablePolicy, Any]:
    """The CBC-TP / CBC policy of a policy file, run folder, checkpoint or shipped name as an
    :class:`ExportablePolicy` (eval mode), and its training config. A missing or corrupted file,
    or a model of another architecture, is a CheckpointError."""
    info = describe(spec)
    if info["algo"] not in EXPORTABLE:
        raise CheckpointError(
            f"'{info['path']}' holds a '{info['algo']}' model; export-onnx takes "
            f"{' or '.join(EXPORTABLE)} pursuer policies"
        )
    scenario = EnvConfig.from_dict(info["train_config"]["env"])
    policy, cfg = load_pursuer_policy(spec, scenario)
    if not isinstance(policy, DeterministicPolicy) or not isinstance(policy.actor, PursuerActors):
        raise CheckpointError(f"'{spec}' does not hold a CBC actor")
    model = ExportablePolicy(policy.actor, getattr(policy, "tp", None)).eval()
    model.requires_grad_(False)
    # A diverged training run can save NaN or infinite weights: its graph would compute NaN.
    tensors = list(model.named_parameters()) + list(model.named_buffers())
    broken = [
        name
        for name, tensor in tensors
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all())
    ]
    if broken:
        more = f" and {len(broken) - 1} more" if len(broken) > 1 else ""
        raise CheckpointError(
            f"'{spec}' holds NaN or infinite weights ({broken[0]}{more}): "
            "the policy cannot be exported"
        )
    return model, cfg


def example_inputs(
    num_pursuers: int,
    batch: int,
    history_length: int,
    with_history: bool,
    dead_fraction: float = 0.2,
    generator: torch.Generator | None = None,
) -> dict[str, Tensor]:
    """Random inputs shaped like the graph's (for tracing and checks): observations and history
    frames ~ N(0, 0.5) (arena units), a ``dead_fraction`` of pursuers dead (rows zeroed, as the
    environment gives them)."""
    n = num_pursuers
    obs = 0.5 * torch.randn(batch, n, n, 8, generator=generator)
    alive = torch.rand(batch, n, generator=generator) >= dead_fraction
    mask = alive[:, other_rows(n)] & alive.unsqueeze(-1)
    out = {"obs": obs * mask.unsqueeze(-1), "alive": alive}
    if with_history:
        hist = 0.5 * torch.randn(batch, history_length, n + 1, 4, generator=generator)
        hist[:, :, :n] *= alive[:, None, :, None]  # dead pursuers are zero in the history
        out["history"] = hist
    return out


def _require_onnx() -> None:
    try:
        import onnx  # noqa: F401
        import onnxscript  # noqa: F401
    except ImportError:
        raise PESError(INSTALL_HINT) from None


def export_onnx(
    spec: str | Path,
    out: str | Path,
    *,
    opset: int | None = None,
    check: bool = True,
) -> dict[str, Any]:
    """Write the policy of ``spec`` (see :func:`load_exportable`) to ``out`` as one ONNX file.

    With ``check``, onnxruntime runs the file on random inputs (3 and the trained number of
    pursuers, a fifth dead) and the largest absolute difference from PyTorch's actions is
    reported as ``max_abs_error``. Returns a summary: ``path``, ``algo``, ``bytes``,
    ``inputs`` and ``outputs`` (name -> shape, symbolic axes as names), ``num_pursuers``
    ("dynamic" or the fixed count of per-pursuer networks), ``history_length``, ``horizon``,
    ``opset``, and with ``check`` ``max_abs_error`` and ``checked_num_pursuers``. An ``opset``
    the exporter cannot write is a PESError.
    """
    _require_onnx()
    model, cfg = load_exportable(spec)
    scenario = cfg.env_config()
    trained_n = scenario.num_pursuers
    history_length = scenario.history_length
    with_tp = model.tp is not None
    shared = len(model.actor.nets) == 1
    n_example = 4 if shared else trained_n  # the example's N: torch.export specialises 0 and 1
    gen = torch.Generator().manual_seed(0)
    inputs = example_inputs(n_example, 2, history_length, with_tp, generator=gen)
    batch = torch.export.Dim("batch")
    dims: dict[str, dict[int, Any]] = {"obs": {0: batch}, "alive": {0: batch}}
    if with_tp:
        dims["history"] = {0: batch}
    if shared:
        pursuers = torch.export.Dim("num_pursuers")
        dims["obs"].update({1: pursuers, 2: pursuers})
        dims["alive"][1] = pursuers
        if with_tp:
            dims["history"][2] = pursuers + 1
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    names = list(inputs)
    outputs = ["actions", "prediction"] if with_tp else ["actions"]
    # The exporter is chatty (progress on stdout, warnings and log lines about its internals):
    # keep stdout for the one JSON object of ``--json`` and stderr for real errors.
    loggers = [logging.getLogger(name) for name in ("torch.onnx", "onnxscript")]
    levels = [logger.level for logger in loggers]
    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        for logger in loggers:
            logger.setLevel(logging.CRITICAL)
        try:
            program = torch.onnx.export(
                model,
                tuple(inputs.values()),
                input_names=names,
                output_names=outputs,
                dynamic_shapes=dims,
                opset_version=opset,
                dynamo=True,
            )
        except Exception as exc:  # noqa: BLE001 - an exporter failure is not a user mistake
            raise RuntimeError(f"the ONNX exporter failed: {exc}") from exc
        finally:
            for logger, level in zip(loggers, levels):
                logger.setLevel(level)
        program.save(str(out), external_data=False)
    written = _opset(out)
    if opset is not None and written != opset:  # the exporter falls back without a word
        out.unlink()
        raise PESError(f"the ONNX exporter cannot write opset {opset} (it wrote {written})")
    summary: dict[str, Any] = {
        "path": str(out),
        "algo": cfg.algo,
        "bytes": out.stat().st_size,
        "num_pursuers": "dynamic" if shared else trained_n,
        "history_length": history_length,
        "horizon": cfg.learner.horizon if with_tp else 0,
        **graph_signature(out),
        "opset": written,
    }
    if check:
        sizes = sorted({3, trained_n}) if shared else [trained_n]
        summary["max_abs_error"] = max(
            max_abs_error(model, out, n, 64, history_length, seed=n) for n in sizes
        )
        summary["checked_num_pursuers"] = sizes
    return summary


def graph_signature(path: str | Path) -> dict[str, dict[str, list]]:
    """``inputs`` and ``outputs`` of an ONNX file: name -> shape (symbolic axes by name)."""
    import onnx

    graph = onnx.load(str(path), load_external_data=False).graph

    def shape(value) -> list:
        dims = value.type.tensor_type.shape.dim
        return [d.dim_param if d.dim_param else d.dim_value for d in dims]

    return {
        "inputs": {v.name: shape(v) for v in graph.input},
        "outputs": {v.name: shape(v) for v in graph.output},
    }


def _opset(path: str | Path) -> int:
    import onnx

    model = onnx.load(str(path), load_external_data=False)
    return next(o.version for o in model.opset_import if o.domain in ("", "ai.onnx"))


def onnx_session(path: str | Path):
    """An onnxruntime CPU session of an exported policy (a PESError without onnxruntime)."""
    try:
        import onnxruntime
    except ImportError:
        raise PESError(INSTALL_HINT) from None
    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = 1
    options.log_severity_level = 3
    return onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def max_abs_error(
    model: ExportablePolicy,
    path: str | Path,
    num_pursuers: int,
    batch: int,
    history_length: int,
    seed: int = 0,
) -> float:
    """Largest absolute difference between onnxruntime's and PyTorch's actions on ``batch``
    random inputs (:func:`example_inputs`) with ``num_pursuers`` pursuers."""
    gen = torch.Generator().manual_seed(seed)
    inputs = example_inputs(
        num_pursuers, batch, history_length, model.tp is not None, generator=gen
    )
    with torch.no_grad():
        expected = model(**inputs)
    expected = expected[0] if isinstance(expected, tuple) else expected
    session = onnx_session(path)
    got = session.run(["actions"], {k: v.numpy() for k, v in inputs.items()})[0]
    return float((torch.from_numpy(got) - expected).abs().max())


__all__ = [
    "EXPORTABLE",
    "ExportablePolicy",
    "example_inputs",
    "export_onnx",
    "graph_signature",
    "load_exportable",
    "max_abs_error",
    "onnx_session",
    "other_rows",
]

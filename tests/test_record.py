"""Episode records: content, round trip, damaged files."""

from __future__ import annotations

import json

import pytest
import torch

import pes
from pes.errors import CheckpointError
from pes.policies import PIDPotentialField
from pes.record import EpisodeRecorder, load_record, render_frames, save_gif, save_record


def _record(**config) -> dict:
    cfg = pes.EnvConfig(max_steps=25, **config).validate()
    env = pes.make_env(cfg, seed=0)
    policy = PIDPotentialField(cfg)
    obs, info = env.reset()
    rec = EpisodeRecorder(env)
    rec.start()
    while not rec.finished:
        obs, _, _, _, info = env.step(policy(obs, info))
        rec.add(info, pred=torch.zeros(3, 2))
    return rec.record()


def test_record_holds_the_contract_keys(tmp_path):
    record = _record(crash_mode="disable", damaged=1)
    for key in ("version", "config", "arena", "buildings", "dt", "agents", "frames", "outcome"):
        assert key in record
    assert record["agents"][-1] == {"id": "evader", "role": "evader"}
    assert len(record["agents"]) == 6 and len(record["buildings"]) == 8
    frame = record["frames"][3]
    assert set(frame) >= {"t", "pos", "vel", "alive", "crashed", "pred"}
    assert len(frame["pos"]) == 6 and len(frame["alive"]) == 5 and sum(frame["alive"]) == 4
    assert frame["t"] == pytest.approx(0.3)
    assert record["outcome"]["steps"] == len(record["frames"]) - 1 == 25
    path = save_record(record, tmp_path / "ep.json")
    assert load_record(path) == json.loads(path.read_text())


def test_damaged_record_files(tmp_path):
    with pytest.raises(CheckpointError, match="not found"):
        load_record(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(CheckpointError, match="not a JSON"):
        load_record(bad)
    bad.write_text(json.dumps({"version": 1}))
    with pytest.raises(CheckpointError, match="missing"):
        load_record(bad)
    record = _record()
    record["version"] = 99
    bad.write_text(json.dumps(record))
    with pytest.raises(CheckpointError, match="version"):
        load_record(bad)


def test_gif_frames_change(tmp_path):
    record = _record()
    frames = list(render_frames(record, every=5))
    assert len(frames) == 6  # steps 0, 5, 10, 15, 20, 25
    import numpy as np

    a, b = np.asarray(frames[0]), np.asarray(frames[-1])
    assert a.shape == b.shape and (a != b).any()
    path = save_gif(record, tmp_path / "ep.gif", every=5)
    from PIL import Image

    with Image.open(path) as image:
        assert image.n_frames == 6

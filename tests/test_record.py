"""Episode records: content, round trip, damaged files."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

import pes
from pes.errors import CheckpointError
from pes.policies import PIDPotentialField
from pes.record import (
    EpisodeRecorder,
    load_record,
    plot_trajectories,
    render_frames,
    save_gif,
    save_mp4,
    save_plot,
    save_record,
)


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


def test_the_header_has_a_legend_naming_the_predictions_where_there_are_some():
    """The orange dots are explained in the header, and only where the policy predicted."""
    from pes.record.render import PREDICTION

    with_pred = _record()
    without = dict(
        with_pred, frames=[{k: v for k, v in f.items() if k != "pred"} for f in with_pred["frames"]]
    )

    def header_has_orange(record) -> bool:
        header = np.asarray(next(iter(render_frames(record))))[:40]
        return bool((np.abs(header.astype(int) - PREDICTION).sum(-1) < 30).any())

    assert header_has_orange(with_pred) and not header_has_orange(without)


def test_mp4_decodes_to_the_rendered_frames(tmp_path):
    import imageio.v2 as imageio
    import numpy as np

    record = _record()
    path = save_mp4(record, tmp_path / "ep.mp4", fps=10, every=5, hold=0.5)
    reader = imageio.get_reader(path, format="FFMPEG")
    try:
        assert reader.get_meta_data()["codec"] == "h264"
        frames = [frame for frame in reader]
    finally:
        reader.close()
    assert len(frames) == 6 + 5  # steps 0, 5, ..., 25, then the last held 0.5 s at 10 fps
    rendered = [np.asarray(image, dtype=float) for image in render_frames(record, every=5)]
    assert frames[0].shape == rendered[0].shape == (640, 600, 3)  # a 40-pixel header
    # Lossy, but each decoded frame is nearest to the picture it encodes (the held ones: the
    # last), and near it.
    for k, frame in enumerate(frames):
        gaps = [np.abs(frame - image).mean() for image in rendered]
        assert int(np.argmin(gaps)) == min(k, 5) and min(gaps) < 2.0


def test_trajectory_plot(tmp_path):
    from PIL import Image

    record = _record(crash_mode="disable", damaged=2)
    path = save_plot(record, tmp_path / "ep.png")
    with Image.open(path) as image:
        pixels = np.asarray(image.convert("RGB"))
    assert pixels.shape[0] > 500 and pixels.shape[1] > 500
    assert (pixels < 250).any(-1).mean() > 0.1  # not blank: buildings, paths, axes
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 20

    # On a given Axes (figures of several episodes): the evader's path is drawn from the record,
    # the two damaged pursuers marked, the TP predictions drawn.
    from matplotlib.figure import Figure

    fig = Figure()
    left, right = fig.subplots(1, 2)
    ax = plot_trajectories(record, ax=right, title="with TP Net", prediction_every=5)
    assert ax is right and ax.get_title() == "with TP Net" and not left.lines
    evader_x = [f["pos"][-1][0] for f in record["frames"]]
    assert any(list(line.get_xdata()) == evader_x for line in ax.lines)
    assert sum(line.get_marker() == "X" for line in ax.lines) == 2
    predicted = [f for f in record["frames"][::5] if f.get("pred")]  # frame 0 has none
    assert len(predicted) == 5
    assert sum(line.get_color() == "#ff7f0e" for line in ax.lines) == 2 * len(predicted)
    with pytest.raises(pes.PESError, match="no frames"):
        plot_trajectories(dict(record, frames=[]))

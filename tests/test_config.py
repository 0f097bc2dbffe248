"""EnvConfig validation, overrides and layouts."""

from __future__ import annotations

import numpy as np
import pytest

import pes
from pes.errors import ConfigError
from pes.sim.layout import grid_layout, load_layout_file, make_layout
from pes.strict import field_docs, parse_override


def test_defaults_are_the_paper_numbers():
    cfg = pes.EnvConfig().validate()
    assert cfg.num_pursuers == 5 and cfg.dt == 0.1 and cfg.max_steps == 500
    assert (cfg.capture_count, cfg.capture_radius, cfg.capture_hold) == (3, 2.0, 5)
    assert (cfg.pursuer_mass, cfg.pursuer_max_speed, cfg.pursuer_max_accel) == (0.8, 10.0, 5.0)
    assert (cfg.evader_mass, cfg.evader_max_speed, cfg.evader_max_accel) == (1.0, 12.0, 4.0)
    assert cfg.pursuer_inertia == (0.006, 0.006, 0.001)
    assert cfg.physics_substeps >= 10 and cfg.body_radius == 0.3
    assert cfg.softplus_k == 1e-3 and cfg.safe_distance == 2.0


def test_evaluation_protocol_resets_the_training_reward():
    shaped = pes.EnvConfig(self_weight=5.0, encirclement_weight=0.5, num_pursuers=4)
    protocol = shaped.for_evaluation(evader_policy="flee")
    assert protocol.disturbance and protocol.crash_mode == "disable"
    assert (protocol.self_weight, protocol.encirclement_weight) == (0.5, 0.0)
    assert protocol.num_pursuers == 4 and protocol.evader_policy == "flee"
    with pytest.raises(ConfigError):
        shaped.for_evaluation(capture_radius=-1.0)


def test_every_field_is_documented():
    docs = field_docs(pes.EnvConfig)
    import dataclasses

    missing = [f.name for f in dataclasses.fields(pes.EnvConfig) if not docs.get(f.name)]
    assert not missing


def test_unknown_key_suggests_the_right_one():
    with pytest.raises(ConfigError, match="did you mean 'num_pursuers'"):
        pes.EnvConfig.from_dict({"num_pursuer": 3})


@pytest.mark.parametrize(
    "values, message",
    [
        ({"pursuer_max_speed": -1.0}, "positive"),
        ({"evader_max_speed": 0}, "positive"),
        ({"capture_count": 6}, "above num_pursuers"),
        ({"num_pursuers": 0}, "at least 1"),
        ({"damaged": 3}, "damaged"),
        ({"disturbance_prob": 1.5}, "disturbance_prob"),
        ({"dt": float("nan")}, "positive"),
        ({"num_pursuers": "five"}, "expected an integer"),
        ({"disturbance": "yes"}, "true or false"),
        ({"dynamics": "rocket"}, "expected one of"),
        ({"crash_mode": "explode"}, "expected one of"),
        ({"evader_policy": "teleport"}, "evader_policy"),
        ({"evader_policy": "ddpg", "evader_model": "no/such/evader.pt"}, "evader-ddpg-paper"),
        ({"layout": "no/such/file.yaml"}, "layout"),
        ({"pursuer_inertia": [1.0, 2.0]}, "expected 3 values"),
        ({"physics_substeps": 1}, "too long"),
    ],
)
def test_impossible_values_are_rejected(values, message):
    with pytest.raises(ConfigError, match=message):
        pes.EnvConfig.from_dict(values)


def test_shipped_evaders_load_and_the_default_is_one_of_them():
    """Every evader name the scenario accepts is a shipped model, the default included."""
    from pes.algos.loading import load_evader_actor
    from pes.models import SHIPPED
    from pes.sim.config import SHIPPED_EVADERS

    assert pes.EnvConfig().evader_model in SHIPPED_EVADERS
    for name in SHIPPED_EVADERS:
        assert name in SHIPPED
        actor = load_evader_actor(name)
        assert not any(p.requires_grad for p in actor.parameters())


def test_a_layout_with_no_room_to_spawn_is_rejected():
    # One block covering the whole middle leaves no room within 10 m of the centre.
    with pytest.raises(ConfigError, match="no free room to spawn the evader"):
        pes.make_env({"grid_rows": 1, "grid_cols": 1, "block_size": 80.0, "removed_blocks": []})


def test_make_env_rejects_bad_arguments():
    with pytest.raises(ConfigError):
        pes.make_env(num_envs=0)
    with pytest.raises(ConfigError):
        pes.make_env(device="tpu")
    with pytest.raises(ConfigError):
        pes.make_env(compiled=True)
    with pytest.raises(ConfigError):
        pes.make_env(pes.EnvConfig(num_pursuers=-2))


def test_overrides_read_yaml_values():
    assert parse_override("num_pursuers=8") == ("num_pursuers", 8)
    assert parse_override("disturbance=true") == ("disturbance", True)
    assert parse_override("removed_blocks=[[0, 0]]") == ("removed_blocks", [[0, 0]])
    with pytest.raises(ConfigError):
        parse_override("num_pursuers")


def test_from_yaml_with_overrides(tmp_path):
    path = tmp_path / "scenario.yaml"
    path.write_text("num_pursuers: 7\ndisturbance: true\n")
    cfg = pes.EnvConfig.from_yaml(path, ["capture_count=4"])
    assert (cfg.num_pursuers, cfg.disturbance, cfg.capture_count) == (7, True, 4)
    path.write_text("num_pursuers: [\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        pes.EnvConfig.from_yaml(path)


def test_grid_layout_generator():
    cfg = pes.EnvConfig()
    layout = grid_layout(cfg)
    assert layout.boxes.shape == (8, 4)  # 3 x 3 minus the central plaza
    assert np.all(layout.boxes[:, 2] - layout.boxes[:, 0] == pytest.approx(18.0))
    centre = [50.0, 50.0]
    inside = [(b[0] <= centre[0] <= b[2]) and (b[1] <= centre[1] <= b[3]) for b in layout.boxes]
    assert not any(inside)
    full = grid_layout(cfg.replace(removed_blocks=[], grid_rows=4, grid_cols=2, street_width=8.0))
    assert full.boxes.shape == (8, 4)


def test_layout_randomness_is_seeded():
    cfg = pes.EnvConfig(block_jitter=3.0, block_removal_prob=0.3, removed_blocks=[])
    a, b = grid_layout(cfg), grid_layout(cfg)
    c = grid_layout(cfg.replace(layout_seed=1))
    assert np.array_equal(a.boxes, b.boxes)
    assert not np.array_equal(a.boxes, c.boxes)
    assert a.boxes.shape[0] < 9 or c.boxes.shape[0] < 9  # something was removed


def test_grid_that_does_not_fit_is_rejected():
    with pytest.raises(ConfigError, match="does not fit"):
        make_layout(pes.EnvConfig(block_size=40.0))


def test_ascii_layout_file(tmp_path):
    path = tmp_path / "city.txt"
    path.write_text("..........\n.##....##.\n.##....##.\n..........\n" * 2 + "..........\n" * 2)
    cfg = pes.EnvConfig(layout=str(path))
    layout = load_layout_file(path, cfg)
    assert layout.boxes.shape == (4, 4)  # each 2 x 2 patch merges into one rectangle
    widths = layout.boxes[:, 2] - layout.boxes[:, 0]
    assert np.allclose(widths, 20.0)
    env = pes.make_env(cfg, seed=0)
    obs, _ = env.reset()
    assert obs.shape == (1, 5, 5, 8)
    path.write_text(".x.\n")
    with pytest.raises(ConfigError, match="only '#' and '.'"):
        load_layout_file(path, cfg)


def test_yaml_layout_file(tmp_path):
    path = tmp_path / "city.yaml"
    path.write_text("buildings:\n  - [20, 20, 35, 35]\n  - [65, 65, 80, 80]\nheights: [30, 40]\n")
    layout = load_layout_file(path, pes.EnvConfig())
    assert layout.boxes.tolist() == [[20, 20, 35, 35], [65, 65, 80, 80]]
    path.write_text("buildings:\n  - [20, 20, 120, 35]\n")
    with pytest.raises(ConfigError, match="outside"):
        load_layout_file(path, pes.EnvConfig())
    path.write_text("buildings:\n  - [30, 20, 20, 35]\n")
    with pytest.raises(ConfigError, match="xmin < xmax"):
        load_layout_file(path, pes.EnvConfig())
    path.write_text("walls: []\n")
    with pytest.raises(ConfigError):
        load_layout_file(path, pes.EnvConfig())

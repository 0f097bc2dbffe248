"""``pes view``: the page, its data, the command, and the page replayed in a real headless
Chromium (skipped where Chromium is absent, unless PES_REQUIRE_EXTRAS=1 as in CI)."""

from __future__ import annotations

import base64
import io
import json
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from PIL import Image, ImageChops

from pes.cli import main
from pes.record import build_page, load_record
from pes.record.viewer import ASSETS, DEFAULT_BUILDING_HEIGHT, scene_data
from tests.conftest import unavailable


@pytest.fixture(scope="module")
def record_path(tmp_path_factory) -> Path:
    """A real short episode: the shipped swarm (with its predictions) or PID(PF), one damaged
    pursuer, crashes allowed to end the episode."""
    from pes.models import is_shipped

    path = tmp_path_factory.mktemp("view") / "episode.json"
    policy = "cbc-tp" if is_shipped("cbc-tp") else "pid-pf"
    argv = ["render", "--policy", policy, "--out", str(path), "--seed", "3"]
    assert main([*argv, "--set", "max_steps=60", "--set", "damaged=1"]) == 0
    return path


def _page_data(page: str) -> dict:
    found = re.search(r'<script id="pes-data" type="application/json">(.*?)</script>', page, re.S)
    assert found, "no episode data in the page"
    return json.loads(found.group(1))


def test_assets_are_package_data():
    from importlib import resources

    folder = resources.files("pes.record") / "viewer"
    for name in ASSETS:
        assert (folder / name).is_file(), name
    assert "three.js authors" in (folder / "three.LICENSE").read_text()


def test_page_is_self_contained(record_path):
    record = load_record(record_path)
    page = build_page(record, title="episode.json")
    # nothing fetched: no external script, style sheet, image or import
    assert not re.search(r"<(script|img|iframe)[^>]*\bsrc=", page, re.I)
    assert not re.search(r"<link\b", page, re.I)
    assert "@import" not in page and "url(http" not in page
    assert page.count("<script") == 3  # data, three.js, viewer
    assert "The MIT License" in page and "window.pesViewer" in page
    data = _page_data(page)
    n = sum(a["role"] == "pursuer" for a in record["agents"])
    assert data["num_pursuers"] == n and len(data["frames"]) == len(record["frames"])
    assert [b[4] for b in data["buildings"]] == record["building_heights"]
    assert data["heights_from"] == "record" and data["altitudes"] == record["altitudes"]
    for v in range(n):  # the first frame where each pursuer is down, from the record's flags
        down = [k for k, f in enumerate(record["frames"]) if not f["alive"][v]]
        assert data["down_step"][v] == (down[0] if down else None)
    assert data["down_step"].count(0) == 1  # the damaged one


def test_page_data_cannot_end_its_script():
    record = json.loads(json.dumps(_minimal_record()))
    record["agents"][0]["id"] = "</script><script>alert(1)</script>"
    page = build_page(record)
    assert "alert(1)</script>" not in page
    assert _page_data(page)["agents"][0]["id"] == record["agents"][0]["id"]


def _minimal_record() -> dict:
    """A hand-made record of two pursuers, without the optional fields."""
    frame = {
        "t": 0.0,
        "pos": [[10.0, 10.0], [20.0, 10.0], [15.0, 15.0]],
        "vel": [[0.0, 0.0]] * 3,
        "alive": [True, True],
        "crashed": [False, False],
    }
    crash = dict(frame, t=0.1, alive=[True, False], crashed=[False, True])
    return {
        "version": 1,
        "config": {"capture_count": 2},
        "arena": [50.0, 40.0],
        "buildings": [[30.0, 20.0, 40.0, 30.0]],
        "dt": 0.1,
        "agents": [
            {"id": "pursuer_0", "role": "pursuer"},
            {"id": "pursuer_1", "role": "pursuer"},
            {"id": "evader", "role": "evader"},
        ],
        "frames": [frame, crash, dict(crash, t=0.2, crashed=[False, False])],
        "outcome": {"success": False, "steps": 2, "crashes": 1},
    }


def test_scene_defaults_for_missing_fields():
    record = _minimal_record()
    data = scene_data(record)
    assert data["heights_from"] == "default"
    assert data["buildings"] == [[30.0, 20.0, 40.0, 30.0, DEFAULT_BUILDING_HEIGHT]]
    assert data["altitudes"] == [10.0, 11.0, 12.0]
    assert data["capture_radius"] == 2.0 and data["capture_count"] == 2
    assert data["down_step"] == [None, 1] and data["crash_step"] == [None, 1]
    record["config"].update(building_height_range=[20.0, 40.0], altitude=5.0, altitude_step=2.0)
    data = scene_data(record)
    assert data["heights_from"] == "config" and data["buildings"][0][4] == 30.0
    assert data["altitudes"] == [5.0, 7.0, 9.0]


def test_view_command(record_path, tmp_path, capsys, monkeypatch):
    out = tmp_path / "pages" / "replay.html"
    assert main(["view", str(record_path), "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    record = load_record(record_path)
    assert summary["page"] == str(out) and summary["bytes"] == out.stat().st_size
    assert summary["steps"] == len(record["frames"]) - 1 and summary["opened"] is False
    opened = []
    monkeypatch.setattr("webbrowser.open", lambda url: opened.append(url) or True)
    assert main(["view", str(record_path), "--open"]) == 0  # default: next to the record
    assert opened == [record_path.with_suffix(".html").resolve().as_uri()]
    assert "wrote" in capsys.readouterr().out


def test_view_mistakes(record_path, tmp_path, capsys):
    wrong_version = json.loads(record_path.read_text())
    wrong_version["version"] = 99
    bad_frames = json.loads(record_path.read_text())
    bad_frames["frames"][1]["pos"] = bad_frames["frames"][1]["pos"][:2]
    files = {
        "version.json": json.dumps(wrong_version),
        "frames.json": json.dumps(bad_frames),
        "other.json": json.dumps({"version": 1, "rows": []}),
        "broken.json": "{not json",
        "list.json": "[1, 2]",
        "agents.json": json.dumps(dict(wrong_version, version=1, agents=5)),
    }
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    cases = [
        ([str(tmp_path / "missing.json")], "not found"),
        ([str(tmp_path / "version.json")], "version 99"),
        ([str(tmp_path / "frames.json")], "frame 1"),
        ([str(tmp_path / "other.json")], "not an episode record"),
        ([str(tmp_path / "broken.json")], "not a JSON"),
        ([str(tmp_path / "list.json")], "not a JSON"),
        ([str(tmp_path / "agents.json")], "agents"),
        ([str(record_path), "--out", str(tmp_path / "page.png")], ".html"),
    ]
    for argv, message in cases:
        assert main(["view", *argv]) == 2, argv
        err = capsys.readouterr().err.strip()
        assert err.startswith("error: ") and message in err and len(err.splitlines()) == 1, err
    proc = subprocess.run(
        [sys.executable, "-m", "pes.cli", "view", str(tmp_path / "frames.json")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    with pytest.raises(SystemExit) as exit_:
        main(["view", "--help"])
    assert exit_.value.code == 0 and "usage: pes view" in capsys.readouterr().out


# --- in a real browser -----------------------------------------------------------------------

CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--no-first-run",
    "--enable-unsafe-swiftshader",  # WebGL on the CPU (SwiftShader), as no GPU is used
    "--use-angle=swiftshader",
    "--window-size=1100,760",
]


@pytest.fixture
def browser():
    """Headless Chromium driven by selenium, with every network request blocked."""
    missing = [tool for tool in ("chromium", "chromedriver") if shutil.which(tool) is None]
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        missing.append("selenium")
    if missing:
        reason = (
            f"needs {' and '.join(missing)} (Debian: apt-get install chromium chromium-driver; "
            "selenium comes with the 'test' extra)"
        )
        unavailable(reason)
    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which("chromium")
    for flag in CHROMIUM_FLAGS:
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(options=options, service=Service(shutil.which("chromedriver")))
    try:
        driver.execute_cdp_cmd("Network.enable", {})
        driver.execute_cdp_cmd("Network.setBlockedURLs", {"urls": ["http://*", "https://*"]})
        yield driver
    finally:
        driver.quit()


def _canvas(driver) -> Image.Image:
    """The WebGL canvas as a picture (the page keeps its drawing buffer)."""
    url = driver.execute_script("return document.querySelector('#scene canvas').toDataURL()")
    return Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB")


def _colours(image: Image.Image) -> int:
    return len(image.quantize(colors=256, method=Image.Quantize.FASTOCTREE).getcolors(256))


def _changed(a: Image.Image, b: Image.Image) -> float:
    """The fraction of pixels that differ between two pictures."""
    diff = ImageChops.difference(a, b).convert("L").point(lambda v: 255 if v > 24 else 0)
    return diff.histogram()[255] / (a.width * a.height)


def _wait_for(browser, expression: str, guard: float = 600.0):
    """The first truthy value of the JavaScript ``expression``, polled; ``guard`` seconds only
    keep a broken page from hanging the tests (a slow machine is not a failure)."""
    started = time.time()
    while time.time() - started < guard:
        value = browser.execute_script(f"return {expression}")
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"never true within {guard:.0f} s: {expression}")


def test_replay_in_headless_chromium(browser, record_path, tmp_path):
    page = tmp_path / "replay.html"
    assert main(["view", str(record_path), "--out", str(page)]) == 0
    record = load_record(record_path)
    n = sum(a["role"] == "pursuer" for a in record["agents"])
    last = len(record["frames"]) - 1

    browser.get(page.as_uri())
    state = _wait_for(browser, "(v => v && (v.ready || v.error) ? v : null)(window.pesViewer)")
    assert state and state["ready"] and state["error"] is None, state
    assert state["vehicles"] == n + 1 and state["trails"] == n + 1
    assert state["buildings"] == len(record["buildings"]) > 0
    assert state["numSteps"] == last and state["step"] == 0
    assert browser.execute_script("return performance.getEntriesByType('resource').length") == 0

    first = _canvas(browser)
    browser.save_screenshot(str(tmp_path / "step0.png"))
    assert _colours(first) > 100  # lit, shaded boxes, vehicles, grid: not a blank canvas
    background = Image.new("RGB", first.size, first.getpixel((2, 2)))
    assert _changed(first, background) > 0.1

    middle = last // 2
    assert browser.execute_script(f"return pesViewer.setStep({middle})") == middle
    text = browser.find_element("id", "readout-time").text
    assert f"step {middle} / {last}" in text
    rows = browser.find_elements("css selector", "#readout-table tbody tr")
    assert len(rows) == n + 1 and all(" m" in r.text for r in rows[:n])
    moved = _canvas(browser)
    browser.save_screenshot(str(tmp_path / f"step{middle}.png"))
    assert _changed(first, moved) > 0.002  # vehicles moved, trails drawn
    if record["frames"][middle].get("pred"):
        assert browser.execute_script("return pesViewer.predictions") > 0

    # the timeline as a person uses it: a key on the slider, the speed, the play button
    scrub = browser.find_element("id", "scrub")
    scrub.send_keys("\ue014")  # arrow right
    assert browser.execute_script("return pesViewer.step") == middle + 1
    browser.execute_script("pesViewer.setStep(0)")
    browser.find_element("css selector", "#speed option[value='8']").click()
    browser.find_element("id", "btn-play").click()  # plays to the end, then stops
    _wait_for(browser, "!(pesViewer.playing || pesViewer.step === 0)")
    state = browser.execute_script("return pesViewer")
    assert state["step"] == last and state["speed"] == 8 and not state["playing"]

    browser.execute_script(f"pesViewer.setStep({last})")
    outcome = browser.find_element("id", "readout-outcome")
    assert outcome.get_attribute("class") in ("captured", "escaped")
    states = browser.find_element("id", "readout-table").text
    assert ("damaged" in states) and (("crashed" in states) == (record["outcome"]["crashes"] > 0))
    browser.execute_script("pesViewer.setView('top')")
    assert _changed(moved, _canvas(browser)) > 0.05

    logs = browser.get_log("browser")
    problems = [e for e in logs if e["level"] == "SEVERE" or e.get("source") == "console-api"]
    assert not problems, problems

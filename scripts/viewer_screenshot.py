"""Make docs/viewer.png: ``pes view`` of the shipped swarm's demo episode, a few steps before
its capture, as headless Chromium draws it.

    python scripts/viewer_screenshot.py [--out docs/viewer.png] [--before 20]

Needs Debian's ``chromium`` and ``chromium-driver`` and selenium (the ``test`` extra). The
episode is ``pes demo``'s (seed 0, disturbance on, crashes disable, the default evader); the
script refuses an episode that the swarm does not capture.
"""

from __future__ import annotations

import argparse
import base64
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from pes.record import load_record  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "docs" / "viewer.png"))
    parser.add_argument("--before", type=int, default=20, help="steps before the capture")
    args = parser.parse_args()
    from selenium import webdriver  # noqa: PLC0415 - an optional dependency
    from selenium.webdriver.chrome.service import Service  # noqa: PLC0415

    with tempfile.TemporaryDirectory() as folder:
        demo = Path(folder) / "demo"
        subprocess.run([sys.executable, "-m", "pes.cli", "demo", "--out", str(demo)], check=True)
        record = load_record(demo / "episode.json")
        if not record["outcome"]["success"]:
            raise SystemExit("the demo episode is not a capture: refusing to picture it as one")
        page = Path(folder) / "view.html"
        view = [sys.executable, "-m", "pes.cli", "view", str(demo / "episode.json")]
        subprocess.run([*view, "--out", str(page)], check=True)
        options = webdriver.ChromeOptions()
        options.binary_location = shutil.which("chromium")
        for flag in (
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--no-first-run",
            "--enable-unsafe-swiftshader",
            "--use-angle=swiftshader",
            "--window-size=1100,760",
        ):
            options.add_argument(flag)
        driver = webdriver.Chrome(options=options, service=Service(shutil.which("chromedriver")))
        try:
            driver.get(page.as_uri())
            started = time.time()
            while time.time() - started < 60:
                state = driver.execute_script("return window.pesViewer || null")
                if state and state["ready"]:
                    break
                time.sleep(0.1)
            step = max(0, record["outcome"]["steps"] - args.before)
            driver.execute_script(f"pesViewer.setStep({step})")
            time.sleep(0.5)
            png = driver.execute_cdp_cmd("Page.captureScreenshot", {"format": "png"})["data"]
            Path(args.out).write_bytes(base64.b64decode(png))
        finally:
            driver.quit()
    print(f"wrote {args.out}: step {step} of a capture in {record['outcome']['steps']} steps")


if __name__ == "__main__":
    main()

"""Rebuild the JavaScript library that ``pes view`` inlines into its pages.

    python scripts/build_viewer_assets.py

Installs three.js and esbuild from npm into a temporary folder, bundles three.js with the
add-ons the viewer uses (OrbitControls, Line2) into one minified script that defines the global
``THREE``, and writes it with three.js's licence to ``src/pes/record/viewer/``. The result is
committed, so neither users nor CI need node or npm; run this only to change the three.js
version (``THREE_VERSION``) or the add-ons (``ENTRY``).
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ASSETS = ROOT / "src" / "pes" / "record" / "viewer"
THREE_VERSION = "0.187.0"
ESBUILD_VERSION = "0.28.2"
ENTRY = """\
export * from 'three';
export { OrbitControls } from 'three/addons/controls/OrbitControls.js';
export { Line2 } from 'three/addons/lines/Line2.js';
export { LineGeometry } from 'three/addons/lines/LineGeometry.js';
export { LineMaterial } from 'three/addons/lines/LineMaterial.js';
"""
BANNER = (
    f"/* three.js {THREE_VERSION} (MIT licence: three.LICENSE) with OrbitControls and Line2, "
    "bundled by scripts/build_viewer_assets.py */"
)


def main() -> int:
    npm = shutil.which("npm")
    if npm is None:
        print("error: npm not found (Debian: apt-get install npm)", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        (work / "package.json").write_text('{"private": true}\n')
        (work / "entry.js").write_text(ENTRY)
        subprocess.run(
            [
                npm,
                "install",
                "--no-audit",
                "--no-fund",
                f"three@{THREE_VERSION}",
                f"esbuild@{ESBUILD_VERSION}",
            ],
            cwd=work,
            check=True,
        )
        esbuild = work / "node_modules" / ".bin" / "esbuild"
        out = ASSETS / "three.min.js"
        subprocess.run(
            [
                str(esbuild),
                "entry.js",
                "--bundle",
                "--format=iife",
                "--global-name=THREE",
                "--minify",
                "--legal-comments=none",
                "--target=es2020",
                f"--banner:js={BANNER}",
                f"--outfile={out}",
            ],
            cwd=work,
            check=True,
        )
        shutil.copy(work / "node_modules" / "three" / "LICENSE", ASSETS / "three.LICENSE")
    print(f"wrote {out} ({out.stat().st_size / 1e3:.0f} kB) and {ASSETS / 'three.LICENSE'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The generated parts of the docs match the code and the committed results."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_generated_docs_are_current():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "gen_docs.py"), "--check"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_readme_starts_with_the_two_commands():
    text = (ROOT / "README.md").read_text()
    head = text[: text.index("##")] if "##" in text else text
    assert "pes demo" in head and "pytest" in head
    ci = (ROOT / ".ci" / "run").read_text()
    # CI runs the README's test command as it stands
    command = next(line for line in head.splitlines() if line.rstrip().endswith("worksteal"))
    assert command.strip() in ci
    # the extras' resolution must not replace the CPU build of torch with a CUDA one
    install = 'pip install torch==2.13.0 && pip install torch==2.13.0 -e ".[test,benchmarl]"'
    assert install in head and install in ci


def test_the_results_readme_quotes_the_reproduction_s_table_iv():
    """results/README.md shows Table IV as the reproduction's report has it (copy the table's
    rows from results/quick/table4.md after each `pes reproduce --report-only`)."""
    report = (ROOT / "results" / "quick" / "table4.md").read_text()
    rows = [line for line in report.splitlines() if line.startswith("|")]
    readme = (ROOT / "results" / "README.md").read_text()
    quoted = readme[readme.index("Table IV (`quick/table4.md`") :].split("\n\n")[1]
    assert quoted.splitlines() == rows

"""Bad input of every kind gets a one-line PESError (a one-line ``error:`` and exit 2 on the
command line), never a traceback and never a silent fix (SPEC §5, issue 30)."""

from __future__ import annotations

import pytest

from pes.cli import main


def one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


# --- 7. argparse mistakes: one line, exit 2 ------------------------------------------------


@pytest.mark.parametrize(
    "argv, message",
    [
        (["eval", "--episodes", "x"], "argument --episodes"),
        (["eval", "--policy", "pid-pf", "--bogus"], "unrecognized arguments: --bogus"),
        (["frobnicate"], "invalid choice: 'frobnicate'"),
        ([], "required: COMMAND"),
        (["view"], "required: EPISODE.json"),
        (["bench", "--num-envs", "x"], "argument --num-envs"),
    ],
)
def test_argparse_mistakes_are_one_line(argv, message, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    err = one_line_error(capsys)
    assert err.startswith("pes") and "error: " in err and message in err
    assert "usage:" not in err


def test_help_still_prints_usage(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["eval", "--help"])
    assert exit_.value.code == 0 and "usage: pes eval" in capsys.readouterr().out

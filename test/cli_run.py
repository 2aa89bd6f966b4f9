"""The command line run in-process for tests (``cli.main.main``): its exit code, and the one line a
bad input gives (exit code 2, one line on stderr, nothing on stdout, no traceback)."""

from __future__ import annotations

import pytest

from skidsteer_power.cli.main import main


def run_cli(argv: list[str]) -> int:
    """Exit code of ``skidsteer-power ARGV`` (argparse rejects a bad option value by SystemExit)."""
    try:
        return main(argv)
    except SystemExit as exit_:
        return int(exit_.code or 0)


def one_line_error(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    """The one stderr line of a run that must fail on bad input (exit code 2, nothing on stdout)."""
    assert run_cli(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and not captured.out and 'Traceback' not in captured.err, captured.err
    return lines[0]

"""The CLI edge: project errors are one line and exit 2; anything else is a bug with a traceback;
a reader that goes away (``... --json | head``) ends the command quietly."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from skidsteer_power.cli import main as cli_main
from skidsteer_power.errors import InputError


def _patched(monkeypatch: pytest.MonkeyPatch, exc: Exception) -> None:
    real = cli_main.build_parser

    def build_parser(only: str | None = None) -> argparse.ArgumentParser:
        parser = real(only)
        (commands,) = (a for a in parser._actions if a.dest == 'command')
        assert isinstance(commands.choices, dict)
        commands.choices['terrains'].set_defaults(func=lambda args: (_ for _ in ()).throw(exc))
        return parser

    monkeypatch.setattr(cli_main, 'build_parser', build_parser)


def test_project_error_is_one_line_and_exit_2(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _patched(monkeypatch, InputError('speed must be > 0'))
    assert cli_main.main(['terrains']) == 2
    assert capsys.readouterr().err == 'skidsteer-power: error: speed must be > 0\n'


def test_a_bug_shows_its_traceback(monkeypatch: pytest.MonkeyPatch) -> None:
    _patched(monkeypatch, ValueError('math domain error'))  # not a user error: must not be swallowed
    with pytest.raises(ValueError, match='math domain error'):
        cli_main.main(['terrains'])


def test_closed_stdout_pipe_exits_quietly() -> None:
    code = (
        'import os, sys\n'
        'r, w = os.pipe(); os.close(r); os.dup2(w, 1)\n'  # the reader is gone, as after `| head`
        'from skidsteer_power.cli.main import main\n'
        "sys.exit(main(['terrains', '--json']))\n"
    )
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=120)
    assert done.stderr == '' and done.returncode == 0


def test_the_help_index_lists_every_command_without_importing_them() -> None:
    """``--help`` reads the command names and helps from the modules' sources (cli.main.command_index):
    the same commands and help texts as the full parser that imports every module."""
    full = cli_main.build_parser()
    (commands,) = (a for a in full._actions if a.dest == 'command')
    index = cli_main.command_index()
    assert isinstance(commands, argparse._SubParsersAction) and set(index) == set(commands.choices)
    for action in commands._choices_actions:
        assert index[action.dest][1] == action.help, action.dest
    code = (
        'import sys\nfrom skidsteer_power.cli.main import main\n'
        "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        "heavy = [m for m in ('numpy', 'scipy', 'rclpy', 'skidsteer_power.maps') if m in sys.modules]\n"
        'print(heavy)\n'
    )
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=120)
    assert done.stdout.strip().splitlines()[-1] == '[]', done.stdout + done.stderr

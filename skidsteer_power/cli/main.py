"""``skidsteer-power`` entry point.

Subcommands live in sibling modules of this package; each defines ``register(subparsers)``, which
adds its parsers and sets ``func`` (a callable ``func(args) -> int | None``) as a default. Modules are
discovered, so a new command needs no edit here.

Errors: a bad argument or file (a :class:`SkidsteerError`, or an OSError on a user's path) gives
one line on stderr and exit code 2, never a traceback; any other exception is a bug and shows its
traceback. When the reader of stdout goes away (``... --json | head``) the command stops quietly.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys
from collections.abc import Sequence
from typing import NoReturn

from skidsteer_power import __version__
from skidsteer_power.cli.common import native_stdout_to_stderr
from skidsteer_power.errors import SkidsteerError

PROG = 'skidsteer-power'
EXIT_USAGE = 2


class OneLineParser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line on stderr and exit code 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f'{self.prog}: error: {message}\n')


def _command_modules() -> list[str]:
    import skidsteer_power.cli as cli_pkg

    names = [m.name for m in pkgutil.iter_modules(cli_pkg.__path__) if m.name not in ('main',)]
    return sorted(n for n in names if not n.startswith('_'))


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog=PROG,
        description='Locomotion power and energy of skid-steered robots on deformable terrain '
        '(SI units; --json for machine-readable output).',
    )
    parser.add_argument('--version', action='version', version=f'{PROG} {__version__}')
    subparsers = parser.add_subparsers(dest='command', metavar='COMMAND', parser_class=OneLineParser)
    for name in _command_modules():
        module = importlib.import_module(f'skidsteer_power.cli.{name}')
        register = getattr(module, 'register', None)
        if register is not None:
            register(subparsers)
    return parser


def fail(message: str) -> int:
    """Print one error line on stderr and return the usage exit code."""
    print(f'{PROG}: error: {message}', file=sys.stderr)
    return EXIT_USAGE


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    func = getattr(args, 'func', None)
    if func is None:
        parser.print_help(sys.stderr)
        return EXIT_USAGE
    try:
        with native_stdout_to_stderr():  # DDS logs must not mix into --json output
            code = func(args)
        sys.stdout.flush()  # a closed pipe shows here, inside the handler, not at interpreter exit
    except SkidsteerError as err:
        return fail(str(err))
    except BrokenPipeError:
        # Python docs (signal, "Note on SIGPIPE"): point stdout at devnull so the final flush is quiet
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as err:
        return fail(f'{err.strerror or err}: {err.filename}' if err.filename else str(err))
    except KeyboardInterrupt:
        return 130
    return int(code or 0)


if __name__ == '__main__':
    sys.exit(main())

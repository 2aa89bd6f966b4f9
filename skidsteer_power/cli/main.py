"""``skidsteer-power`` entry point.

Subcommands live in sibling modules of this package; each defines ``register(subparsers)``, which
adds its parsers and sets ``func`` (a callable ``func(args) -> int | None``) as a default. Modules are
discovered, so a new command needs no edit here.

Errors: a bad argument or file gives one line on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from collections.abc import Sequence

from skidsteer_power import __version__
from skidsteer_power.cli.common import native_stdout_to_stderr
from skidsteer_power.errors import SkidsteerError

PROG = 'skidsteer-power'
EXIT_USAGE = 2


class OneLineParser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line on stderr and exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
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
    except (SkidsteerError, ValueError) as err:
        return fail(str(err))
    except OSError as err:
        return fail(f'{err.strerror or err}: {err.filename}' if err.filename else str(err))
    except KeyboardInterrupt:
        return 130
    return int(code or 0)


if __name__ == '__main__':
    sys.exit(main())

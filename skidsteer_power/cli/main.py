"""``skidsteer-power`` entry point.

Subcommands live in sibling modules of this package; each defines ``register(subparsers)``, which
adds its parsers and sets ``func`` (a callable ``func(args) -> int | None``) as a default. Modules are
discovered, so a new command needs no edit here.

Start-up: a command imports only its own module (:func:`command_index` finds which one from the
modules' ``subparsers.add_parser('NAME', help='...')`` calls, read with :mod:`ast`, not imported), and
``skidsteer-power --help`` imports none: its list of commands comes from the same index
(benchmarks/bench_drive.py measures it against a 0.3 s goal).

Errors: a bad argument or file (a :class:`SkidsteerError`, or an OSError on a user's path) gives
one line on stderr and exit code 2, never a traceback; any other exception is a bug and shows its
traceback. When the reader of stdout goes away (``... --json | head``) the command stops quietly.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import os
import pkgutil
import re
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn, TextIO

from skidsteer_power import __version__
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


INDEX_CACHE = 'cli_index.json'
"""The command index kept in the cache folder (skidsteer_power.cache), keyed by the command modules'
sizes and modification times: a changed module is read again."""


def command_index() -> dict[str, tuple[str, str | None]]:
    """{command: (module, help or None)} from each command module's source: the literal first
    argument and ``help=`` of the ``<first parameter of register>.add_parser(...)`` calls in its
    functions taking that parameter. A module whose calls are not literal is left out (it is
    imported whenever the full parser is built). Kept in :data:`INDEX_CACHE` between runs."""
    import json

    import skidsteer_power.cli as cli_pkg
    from skidsteer_power.cache import default_cache_dir

    folder = Path(cli_pkg.__path__[0])
    modules = _command_modules()
    try:
        key = [[m, *(lambda st: (st.st_mtime_ns, st.st_size))((folder / f'{m}.py').stat())] for m in modules]
    except OSError:
        return _read_index(folder, modules)
    cached = default_cache_dir() / INDEX_CACHE
    try:
        data = json.loads(cached.read_text(encoding='utf-8'))
        if data['key'] == key:
            return {name: (entry[0], entry[1]) for name, entry in data['index'].items()}
    except (OSError, ValueError, KeyError, TypeError, IndexError):
        pass  # missing or stale: read the sources
    index = _read_index(folder, modules)
    try:
        cached.parent.mkdir(parents=True, exist_ok=True)
        temporary = cached.with_name(f'{INDEX_CACHE}.{os.getpid()}')
        temporary.write_text(json.dumps({'key': key, 'index': index}), encoding='utf-8')
        temporary.replace(cached)
    except OSError:
        pass  # a read-only home: read the sources every time
    return index


def _read_index(folder: Path, modules: list[str]) -> dict[str, tuple[str, str | None]]:
    index: dict[str, tuple[str, str | None]] = {}
    for module in modules:
        try:
            functions = _functions_adding_parsers((folder / f'{module}.py').read_text(encoding='utf-8'))
        except (OSError, SyntaxError, ValueError):
            continue
        receiver = next((f.args.args[0].arg for f in functions if f.name == 'register' and f.args.args), None)
        for func in functions:
            if receiver is not None and func.args.args and func.args.args[0].arg == receiver:
                index.update(_registered(func, receiver, module))
    return index


def _functions_adding_parsers(source: str) -> list[ast.FunctionDef]:
    """The module-level functions of ``source`` that call ``add_parser``, and ``register``, parsed
    one by one (parsing only those keeps ``--help`` fast); the whole source if a piece does not
    parse alone."""
    pieces = [
        p
        for p in re.split(r'(?m)^(?=def )', source)
        if p.startswith('def ') and ('add_parser(' in p or p.startswith('def register('))
    ]
    try:
        trees = [ast.parse(p) for p in pieces]
    except SyntaxError:
        trees = [ast.parse(source)]
    return [node for tree in trees for node in tree.body if isinstance(node, ast.FunctionDef)]


def _registered(func: ast.FunctionDef, receiver: str, module: str) -> dict[str, tuple[str, str | None]]:
    """{name: (module, help)} of the literal ``receiver.add_parser(NAME, help=...)`` calls in ``func``."""
    found: dict[str, tuple[str, str | None]] = {}
    for node in ast.walk(func):
        if not isinstance(node, ast.Call):
            continue
        target = node.func
        if not (isinstance(target, ast.Attribute) and target.attr == 'add_parser'):
            continue
        if not (isinstance(target.value, ast.Name) and target.value.id == receiver):
            continue
        try:
            name = ast.literal_eval(node.args[0])
            helps = [ast.literal_eval(k.value) for k in node.keywords if k.arg == 'help']
        except (ValueError, IndexError, TypeError, SyntaxError):
            continue
        if isinstance(name, str):
            found[name] = (module, helps[0] if helps and isinstance(helps[0], str) else None)
    return found


def _top_parser() -> tuple[OneLineParser, argparse._SubParsersAction[OneLineParser]]:
    parser = OneLineParser(
        prog=PROG,
        description='Locomotion power and energy of skid-steered robots on deformable terrain '
        '(SI units; --json for machine-readable output).',
    )
    parser.add_argument('--version', action='version', version=f'{PROG} {__version__}')
    subparsers = parser.add_subparsers(dest='command', metavar='COMMAND', parser_class=OneLineParser)
    return parser, subparsers


def help_parser() -> argparse.ArgumentParser:
    """The top-level parser with every command's name and help but none of their options (no
    command module imported): what ``--help`` and a bare ``skidsteer-power`` print."""
    parser, subparsers = _top_parser()
    for name, (_module, text) in sorted(command_index().items()):
        subparsers.add_parser(name, help=text, add_help=False)
    return parser


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The full parser; with ``only`` a command name of :func:`command_index`, just that command's
    module (the others are not imported)."""
    parser, subparsers = _top_parser()
    index = command_index() if only is not None else {}
    modules = [index[only][0]] if only in index else _command_modules()
    for name in modules:
        module = importlib.import_module(f'skidsteer_power.cli.{name}')
        register = getattr(module, 'register', None)
        if register is not None:
            register(subparsers)
    return parser


def fail(message: str) -> int:
    """Print one error line on stderr and return the usage exit code."""
    print(f'{PROG}: error: {message}', file=sys.stderr)
    return EXIT_USAGE


def _command_of(argv: Sequence[str]) -> str | None:
    """The command word of a command line (its first argument not an option), if any."""
    return next((a for a in argv if not a.startswith('-')), None)


def _note(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: TextIO | None = None,
    line: str | None = None,
) -> None:
    """An old spelling's FutureWarning on the command line: ``note: message``, one line on stderr;
    any other warning as Python shows it."""
    if issubclass(category, FutureWarning):
        print(f'note: {message}', file=sys.stderr)
    else:
        _SHOW_WARNING(message, category, filename, lineno, file, line)


_SHOW_WARNING = warnings.showwarning


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    command = _command_of(argv)
    if command is None:  # --help, --version or nothing: no command module is needed
        light = help_parser()
        light.parse_args(argv)  # exits for --help and --version
        light.print_help(sys.stderr)
        return EXIT_USAGE
    parser = build_parser(command)
    args = parser.parse_args(argv)
    func = getattr(args, 'func', None)
    if func is None:
        parser.print_help(sys.stderr)
        return EXIT_USAGE
    from skidsteer_power.cli.common import native_stdout_to_stderr

    try:
        with native_stdout_to_stderr(), warnings.catch_warnings():  # DDS logs apart from --json
            warnings.showwarning = _note  # an old spelling's FutureWarning: one line, no source line
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

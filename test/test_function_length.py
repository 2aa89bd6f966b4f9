"""No function or method of skidsteer_power is longer than :data:`MAX_LINES` lines (issue 38): a long
one is split into named steps. Length is ``end_lineno - lineno + 1`` of its ``def`` (decorators not
counted, its docstring and nested functions counted). Read from the source with :mod:`ast`."""

from __future__ import annotations

import ast
from pathlib import Path

import skidsteer_power

ROOT = Path(skidsteer_power.__file__).parent
MAX_LINES = 80


def long_functions(source: str, limit: int = MAX_LINES) -> list[tuple[int, str, int]]:
    """(first line, name, length) of every function or method of ``source`` (nested ones too)
    longer than ``limit`` lines, in source order."""
    found = [
        (node.lineno, node.name, (node.end_lineno or node.lineno) - node.lineno + 1)
        for node in ast.walk(ast.parse(source))
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
    ]
    return sorted(f for f in found if f[2] > limit)


def test_the_checker_finds_a_long_function_and_method() -> None:
    body = ''.join(f'    x{k} = {k}\n' for k in range(80))  # 80 lines: with the def, 81
    source = (
        f'def short():\n    return 1\n\n\n@decorated\ndef long():\n{body}\n\n'
        f'class C:\n    def method(self):\n{body.replace("    ", "        ")}\n'
        f'def exactly_80():\n{body[: body.rindex("    x79")]}'
    )
    # the decorator is not counted (long starts at its def, line 6); exactly 80 lines pass
    assert long_functions(source) == [(6, 'long', 81), (90, 'method', 81)]
    assert long_functions('async def a():\n    pass\n    pass\n', limit=2) == [(1, 'a', 3)]


def test_no_function_is_longer_than_the_limit() -> None:
    files = sorted(ROOT.rglob('*.py'))
    assert len(files) > 150  # every module was read (196 on 2026-12-04)
    too_long = [
        f'{path.relative_to(ROOT.parent)}:{line} {name} {length} lines'
        for path in files
        for line, name, length in long_functions(path.read_text(encoding='utf-8'))
    ]
    assert not too_long, f'longer than {MAX_LINES} lines (split into named steps):\n' + '\n'.join(too_long)

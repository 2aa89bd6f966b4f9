"""At most :data:`MAX_ANY` explicit ``typing.Any`` in skidsteer_power, each with its reason (issue 38:
"at most 20 explicit `Any` in the package, each with its reason"). A use is a name ``Any`` or an
attribute ``typing.Any`` in the code (its import not counted); its reason is a ``# Any: ...`` comment
on the same line. Read from the source with :mod:`ast`."""

from __future__ import annotations

import ast
from pathlib import Path

import skidsteer_power

ROOT = Path(skidsteer_power.__file__).parent
MAX_ANY = 20
REASON = '# Any:'


def any_uses(source: str) -> list[tuple[int, bool]]:
    """(line, has a reason) of every explicit ``Any`` in ``source``, in source order."""
    lines = source.splitlines()
    found = [
        node.lineno
        for node in ast.walk(ast.parse(source))
        if (isinstance(node, ast.Name) and node.id == 'Any')
        or (isinstance(node, ast.Attribute) and node.attr == 'Any')
    ]
    return [(line, REASON in lines[line - 1]) for line in sorted(found)]


def test_the_counter_finds_names_and_attributes_but_not_imports() -> None:
    source = (
        'from typing import Any\n'
        'import typing\n'
        'x: Any = 1  # Any: a reason\n'
        'def f(a: typing.Any) -> list[Any]:\n'
        '    return [a]\n'
    )
    # hand count: line 3 (with reason), line 4 twice (typing.Any and Any, no reason); the import not
    assert any_uses(source) == [(3, True), (4, False), (4, False)]


def test_few_explicit_any_each_with_its_reason() -> None:
    files = sorted(ROOT.rglob('*.py'))
    assert len(files) > 150  # every module was read
    uses = [
        (f'{path.relative_to(ROOT.parent)}:{line}', reason)
        for path in files
        for line, reason in any_uses(path.read_text(encoding='utf-8'))
    ]
    unexplained = [where for where, reason in uses if not reason]
    assert not unexplained, f'explicit Any without a "{REASON} why" comment on its line:\n' + '\n'.join(
        unexplained
    )
    assert len(uses) <= MAX_ANY, f'{len(uses)} explicit Any (at most {MAX_ANY}):\n' + '\n'.join(
        where for where, _ in uses
    )

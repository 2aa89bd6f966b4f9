"""No import cycle between the modules of any package (issue 38), counting every import:
top-level, inside functions (lazy) and under ``if TYPE_CHECKING`` (which import-linter's contracts
skip here: ``exclude_type_checking_imports``). Read from the source with :mod:`ast`, so the test
cannot be fooled by import order or caching."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import skidsteer_power

ROOT = Path(skidsteer_power.__file__).parent
PACKAGES = tuple(sorted(p.name for p in ROOT.iterdir() if (p / '__init__.py').is_file()))
"""Every package of skidsteer_power: the modules of none may form a cycle."""


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def _imports(path: Path, package: str) -> set[str]:
    """Modules of ``package`` that ``path`` imports (``from package import module`` included)."""
    tree = ast.parse(path.read_text())
    here = _module_name(path)
    prefix = f'skidsteer_power.{package}'
    found: set[str] = set()
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module, *(f'{node.module}.{a.name}' for a in node.names)]
        for name in names:
            if name.startswith(prefix + '.') and name != here:
                found.add('.'.join(name.split('.')[:3]))
    return found - {here}


def _graph(package: str) -> dict[str, set[str]]:
    files = sorted((ROOT / package).glob('*.py'))
    modules = {_module_name(f) for f in files if f.name != '__init__.py'}
    return {_module_name(f): _imports(f, package) & modules for f in files if f.name != '__init__.py'}


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` (as the list of modules along it), or None."""
    state: dict[str, int] = {}  # 1 on the current path, 2 done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt) :], nxt]
            if nxt not in state and (found := visit(nxt)) is not None:
                return found
        state[node] = 2
        path.pop()
        return None

    for start in sorted(graph):
        if start not in state and (found := visit(start)) is not None:
            return found
    return None


def test_the_cycle_finder_finds_a_cycle() -> None:
    assert _cycle({'a': {'b'}, 'b': {'c'}, 'c': {'a'}}) == ['a', 'b', 'c', 'a']
    assert _cycle({'a': {'b'}, 'b': set(), 'c': {'a', 'b'}}) is None


@pytest.mark.parametrize('package', PACKAGES)
def test_no_import_cycle_inside(package: str) -> None:
    graph = _graph(package)
    assert graph  # the package's modules were found
    assert _cycle(graph) is None, ' -> '.join(_cycle(graph) or [])


def _every_import(path: Path, modules: set[str]) -> set[str]:
    """Modules of skidsteer_power that ``path`` imports, anywhere in it; ``from pkg import mod``
    counts as an import of pkg.mod (and of pkg only for the names that are not modules)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            subs = [f'{node.module}.{a.name}' for a in node.names]
            names = [s for s in subs if s in modules]
            if len(names) < len(subs):
                names.append(node.module)
        for name in names:
            while name and name not in modules:
                name = name.rpartition('.')[0]
            if name:
                found.add(name)
    return found


def test_no_import_cycle_between_any_two_modules() -> None:
    """Across packages too (issue 38: 'no import cycle between modules, inside a package or not')."""
    files = {_module_name(f): f for f in sorted(ROOT.rglob('*.py'))}
    modules = set(files) - {'skidsteer_power'}
    graph = {name: _every_import(path, modules) - {name} for name, path in files.items() if name in modules}
    assert len(graph) > 150  # every module was read (195 on 2026-12-04)
    assert _cycle(graph) is None, ' -> '.join(_cycle(graph) or [])

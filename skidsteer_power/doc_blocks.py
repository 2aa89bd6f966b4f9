"""Generated blocks in the Markdown docs: the one marker syntax and its parser (issue 38, "Docs that
drift": every figure in README.md and docs/*.md is written by a command between markers, and a check
fails when the text and the command disagree).

A block is the text between two HTML comments (invisible in rendered Markdown)::

    <!-- BEGIN generated: NAME -->
    (written by NAME's generator)
    <!-- END generated: NAME -->

``generated`` blocks are fast and deterministic (physics figures, a command's printed figures, API
text read from the code): ``python -m tools.docs_figures --check`` regenerates each and fails on any
difference. ``measured`` blocks (``<!-- BEGIN measured: NAME -->``) come from a slow command (the
main job, a benchmark): the fast check only requires their first line to name the command and the
date (:data:`MEASURED_LINE`); ``python -m tools.docs_figures --measured NAME`` reruns it. A block
whose BEGIN marker ends its line holds whole lines; otherwise it is inline (a figure inside a
sentence: ``<!-- BEGIN generated: x -->+107.3 %<!-- END generated: x -->``).

Pure text, no imports from the package: the node parameter tables (``nodes/param_files.py``) and
``tools/docs_figures.py`` (which also fills the command examples of ``apps/doc_examples.py``) use it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

KINDS = ('generated', 'measured')
MARKER = re.compile(r'<!-- (?P<edge>BEGIN|END) (?P<kind>[a-z]+): (?P<name>.+?) -->')
# Markers of earlier rounds: a doc still holding one is an error, not a block silently left unchecked.
STALE_MARKERS = re.compile(r'<!-- (example: .*?|params:\S+ .*?|/params) -->')
MEASURED_LINE = re.compile(r'Measured (?P<date>\d{4}-\d{2}-\d{2}) with `(?P<command>[^`]+)`')


class DocBlockError(ValueError):
    """Markers that do not pair up, or a block the docs tool cannot fill."""


@dataclass(frozen=True)
class Block:
    """One marked block of a document: its kind, name, body (the text between the markers) and where
    the body lies in the document (``start``/``stop``, character offsets; ``line``, 1-based)."""

    kind: str
    name: str
    body: str
    start: int
    stop: int
    line: int

    @property
    def inline(self) -> bool:
        """True for a block inside a line (its body does not start with a newline)."""
        return not self.body.startswith('\n')


def begin_marker(kind: str, name: str) -> str:
    return f'<!-- BEGIN {kind}: {name} -->'


def end_marker(kind: str, name: str) -> str:
    return f'<!-- END {kind}: {name} -->'


def _fenced(text: str) -> list[tuple[int, int]]:
    """The (start, stop) offsets of ``text``'s fenced code blocks (lines opening with three backticks):
    a marker shown inside one is an example of the syntax, not a block."""
    spans, start, at = [], -1, 0
    for line in text.splitlines(keepends=True):
        if line.lstrip().startswith('```'):
            if start < 0:
                start = at
            else:
                spans.append((start, at + len(line)))
                start = -1
        at += len(line)
    return spans


def find_blocks(text: str, where: str = '<text>') -> list[Block]:
    """Every block of ``text`` in order; :class:`DocBlockError` (naming ``where`` and the line) for an
    unknown kind, a BEGIN without its END, an END without its BEGIN, nested blocks or a stale marker.
    Markers inside a fenced code block are text (examples of the syntax); a block's body may hold
    fences."""
    fences = _fenced(text)

    def shown(m: re.Match[str]) -> bool:
        return not any(a <= m.start() < b for a, b in fences)

    stale = next((m for m in STALE_MARKERS.finditer(text) if shown(m)), None)
    if stale:
        raise DocBlockError(
            f'{where}:{_line(text, stale.start())}: marker {stale[0]!r} of an earlier syntax: use '
            f'{begin_marker("generated", "NAME")} ... {end_marker("generated", "NAME")}'
        )
    blocks: list[Block] = []
    open_: re.Match[str] | None = None
    for m in filter(shown, MARKER.finditer(text)):
        at = f'{where}:{_line(text, m.start())}'
        if m['kind'] not in KINDS:
            raise DocBlockError(f'{at}: unknown block kind {m["kind"]!r} (one of {", ".join(KINDS)})')
        if m['edge'] == 'BEGIN':
            if open_ is not None:
                raise DocBlockError(f'{at}: {m[0]} inside the block {open_["name"]!r}')
            open_ = m
            continue
        if open_ is None or (open_['kind'], open_['name']) != (m['kind'], m['name']):
            raise DocBlockError(f'{at}: {m[0]} without its BEGIN marker')
        body = text[open_.end() : m.start()]
        blocks.append(Block(m['kind'], m['name'], body, open_.end(), m.start(), _line(text, open_.start())))
        open_ = None
    if open_ is not None:
        raise DocBlockError(f'{where}:{_line(text, open_.start())}: {open_[0]} without its END marker')
    return blocks


def body_for(block: Block, content: str) -> str:
    """The body that holds ``content`` in ``block``'s form: whole lines (``content`` ends with a newline;
    one is added) for a line block, the stripped text for an inline one."""
    if block.inline:
        return content.strip()
    return '\n' + (content if content.endswith('\n') else content + '\n')


def replace_bodies(text: str, bodies: dict[tuple[str, str], str], where: str = '<text>') -> str:
    """``text`` with the body of each block named in ``bodies`` (by (kind, name)) set to its content
    (:func:`body_for`); other blocks and the text outside the markers stay as they are."""
    out, at = [], 0
    for block in find_blocks(text, where):
        content = bodies.get((block.kind, block.name))
        if content is None:
            continue
        out += [text[at : block.start], body_for(block, content)]
        at = block.stop
    return ''.join([*out, text[at:]])


def replace_block(text: str, kind: str, name: str, content: str, where: str = '<text>') -> str:
    """``text`` with block ``name``'s body set to ``content``; :class:`DocBlockError` if it has none."""
    if not any((b.kind, b.name) == (kind, name) for b in find_blocks(text, where)):
        raise DocBlockError(f'{where}: no block {begin_marker(kind, name)}')
    return replace_bodies(text, {(kind, name): content}, where)


def _line(text: str, offset: int) -> int:
    return text.count('\n', 0, offset) + 1

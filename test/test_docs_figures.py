"""The figures of README.md, docs/*.md and bags/README.md are what their commands print (issue 38,
"Docs that drift"): ``python -m tools.docs_figures --check`` regenerates every generated block and
fails on a difference; the marker parser refuses markers that do not pair up."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from skidsteer_power.doc_blocks import (
    DocBlockError,
    begin_marker,
    end_marker,
    find_blocks,
    replace_block,
    replace_bodies,
)
from tools import docs_figures

REQUIRE_SHARED = os.environ.get('SKIDSTEER_REQUIRE_SHARED') == '1'


def test_every_doc_block_is_its_commands_output() -> None:
    """The whole check, as CI runs it; it needs ../shared for the Neato block (fails without it in CI)."""
    if not docs_figures.SHARED.is_dir() and REQUIRE_SHARED:
        pytest.fail(f'{docs_figures.SHARED} is missing and SKIDSTEER_REQUIRE_SHARED=1 requires it')
    assert docs_figures.main(['--check']) == 0


def test_the_drifting_figures_of_issue_38_are_generated_blocks() -> None:
    names = {f.block.name for f in docs_figures.collect(docs_figures.doc_files())}
    for name in (
        'calibrate walkthrough',  # docs/CALIBRATION.md
        'calibrate walkthrough energy',  # README.md
        'neato validate',  # docs/ROS.md
        'maps api',  # docs/INTERFACES.md
        'layers',
        'layers table',
        'params des_driver',
        'main job',  # measured
    ):
        assert name in names


def test_a_hand_edited_figure_is_caught(tmp_path: Path) -> None:
    """A copy of bags/README.md with one message count changed (the track bag's /cmd_vel: 98 s at
    25 Hz = 2450 intervals, 2451 messages): the check names that block and writes nothing; the
    rewrite restores the command's text."""
    doc = (docs_figures.ROOT / 'bags' / 'README.md').read_text(encoding='utf-8')
    block = next(b for b in find_blocks(doc) if b.name == 'bundled bags')
    row = '| `test_robot_track_sand_bin.mcap` | `test_robot_track` | `sand_bin` | 98.0 | 2451 |'
    assert row in block.body
    edited_body = block.body.replace(row, row.replace('2451', '2452'))
    edited = doc[: block.start] + edited_body + doc[block.stop :]
    copy = tmp_path / 'README.md'
    copy.write_text(edited, encoding='utf-8')
    stale = docs_figures.run([copy], check=True, only={'bundled bags'})
    assert len(stale) == 1 and 'bundled bags' in stale[0]
    assert copy.read_text(encoding='utf-8') == edited  # --check writes nothing
    assert docs_figures.run([copy], check=False, only={'bundled bags'})
    assert copy.read_text(encoding='utf-8') == doc


def test_a_measured_block_must_name_its_command_and_date(tmp_path: Path) -> None:
    good = (
        f'{begin_marker("measured", "main job")}\n'
        'Measured 2026-12-02 with `bash bags/twin_main_job.sh OUT`.\n\n| t |\n'
        f'{end_marker("measured", "main job")}\n'
    )
    path = tmp_path / 'measured.md'
    path.write_text(good, encoding='utf-8')
    assert docs_figures.run([path], check=True) == []
    path.write_text(good.replace('Measured 2026-12-02 with', 'Measured with'), encoding='utf-8')
    (why,) = docs_figures.run([path], check=True)
    assert 'Measured YYYY-MM-DD with `bash bags/twin_main_job.sh OUT`' in why


def test_an_unknown_name_or_a_stale_marker_is_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / 'unknown.md'
    path.write_text(f'{begin_marker("generated", "no such")}x{end_marker("generated", "no such")}\n')
    assert docs_figures.main(['--check', str(path)]) == 2
    assert "no generator named 'no such'" in capsys.readouterr().err
    path.write_text('<!-- example: skidsteer-power info x.mcap -->\n```text\n```\n')
    assert docs_figures.main(['--check', str(path)]) == 2
    assert 'earlier syntax' in capsys.readouterr().err


def test_blocks_pair_up_and_replace_only_their_body() -> None:
    text = (
        'a <!-- BEGIN generated: x -->1<!-- END generated: x --> b\n'
        '<!-- BEGIN generated: y -->\nold\n<!-- END generated: y -->\nc\n'
    )
    x, y = find_blocks(text)
    assert (x.name, x.inline, x.body, x.line) == ('x', True, '1', 1)
    assert (y.name, y.inline, y.body, y.line) == ('y', False, '\nold\n', 2)
    new = replace_bodies(text, {('generated', 'x'): ' 2 \n', ('generated', 'y'): 'new'})
    assert new == text.replace('-->1<', '-->2<').replace('\nold\n', '\nnew\n')
    assert replace_block(new, 'generated', 'y', 'old\n') == text.replace('-->1<', '-->2<')
    with pytest.raises(DocBlockError, match='no block'):
        replace_block(text, 'generated', 'z', '')
    for bad, why in (
        ('<!-- BEGIN generated: x -->', 'without its END'),
        ('<!-- END generated: x -->', 'without its BEGIN'),
        ('<!-- BEGIN generated: x --><!-- END generated: y -->', 'without its BEGIN'),
        ('<!-- BEGIN generated: x --><!-- BEGIN generated: y -->', 'inside the block'),
        ('<!-- BEGIN figures: x --><!-- END figures: x -->', 'unknown block kind'),
    ):
        with pytest.raises(DocBlockError, match=why):
            find_blocks('line\n' + bad, 'doc.md')

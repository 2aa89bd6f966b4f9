"""docs/ROS.md's command examples are the output of the commands they quote (issue 37): a block
named ``skidsteer-power ARGS`` is regenerated and compared (tools/docs_figures.py); the check also
fails on a block whose output was edited by hand."""

from __future__ import annotations

from pathlib import Path

import pytest

from skidsteer_power.apps.doc_examples import example_block, is_example, run_example
from skidsteer_power.doc_blocks import find_blocks
from tools import docs_figures

ROS_MD = docs_figures.ROOT / 'docs' / 'ROS.md'
INFO = 'skidsteer-power info bags/test_robot_track_sand_bin.mcap'


def test_ros_md_examples_are_the_commands_output() -> None:
    examples = [b for b in find_blocks(ROS_MD.read_text(encoding='utf-8')) if is_example(b.name)]
    assert {INFO, 'skidsteer-power call --help'} <= {b.name for b in examples}
    for block in examples:
        assert block.body == '\n' + example_block(block.name), block.name


def test_a_hand_edited_number_is_caught(tmp_path: Path) -> None:
    text = ROS_MD.read_text(encoding='utf-8')
    edited = text.replace('Messages:          10295', 'Messages:          10296', 1)
    assert edited != text  # bags/README.md's table: 2451 + 4901 + 3 x 981 = 10295 messages
    copy = tmp_path / 'ROS.md'
    copy.write_text(edited, encoding='utf-8')
    stale = docs_figures.run([copy], check=True, only={INFO})
    assert len(stale) == 1 and INFO in stale[0]


def test_an_example_runs_only_skidsteer_power() -> None:
    with pytest.raises(ValueError, match='must run skidsteer-power'):
        run_example('rm -rf /')

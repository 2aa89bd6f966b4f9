"""docs/ROS.md's command examples are the output of the commands they quote (issue 37): regenerated
here and compared; the check also fails on a block whose output was edited by hand."""

from __future__ import annotations

from skidsteer_power.apps.doc_examples import BLOCK, DEFAULT_FILES, main, render


def test_docs_examples_are_the_commands_output() -> None:
    text = DEFAULT_FILES[0].read_text(encoding='utf-8')
    assert len(BLOCK.findall(text)) >= 2  # the info example and the call help at least
    assert main(['--check']) == 0


def test_a_hand_edited_number_is_caught() -> None:
    text = DEFAULT_FILES[0].read_text(encoding='utf-8')
    edited = text.replace('Messages:          10295', 'Messages:          10296', 1)
    assert edited != text
    _, changed = render(edited)
    assert any(c.startswith('skidsteer-power info') for c in changed)

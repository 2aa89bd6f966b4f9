"""The goal table of docs/BENCHMARKS.md rendered from a benchmark run's figures (benchmarks/docs.py),
on a small hand-made run: the expected rows are written out by hand below."""

from benchmarks.docs import BEGIN, END, existing_rows, goal_table, replace_named, update_doc
from benchmarks.harness import Figure

RUN = '2026-12-02, 2 cores, load 3.0'
FESS = [
    Figure('fess: track 8 x 16 map', 0.0083, 's', '< 0.05 s', True),
    Figure('fess: one online solve', 0.00158, 's', '< 0.001 s', False, 'load 4.5'),
]
MAPS = [Figure('maps: vectorized queries', 3.8e6, '1/s')]


def test_rows_carry_section_goal_value_and_met() -> None:
    table = goal_table([('fess', FESS), ('maps', MAPS)], RUN)
    assert table.splitlines() == [
        '| benchmark | figure | goal | measured | met | run |',
        '| --- | --- | --- | ---: | --- | --- |',
        f'| fess | track 8 x 16 map | < 0.05 s | 0.0083 s | yes | {RUN} |',
        f'| fess | one online solve (load 4.5) | < 0.001 s | 0.00158 s | **no** | {RUN} |',
        f'| maps | vectorized queries | - | 3.8e+06 1/s | - | {RUN} |',
        '',
        '1 goal(s) missed in this table.',
    ]


def test_a_pipe_in_a_name_does_not_split_the_row() -> None:
    table = goal_table([('des', [Figure('des: a | b', 1.0, 'ms')])], RUN)
    assert '| des | a \\| b | - | 1 ms | - |' in table
    assert existing_rows(f'{BEGIN}\n{table}\n{END}') == {'des': [table.splitlines()[2]]}


def test_the_hand_written_text_stays_and_a_partial_run_keeps_other_areas() -> None:
    doc = '# Benchmarks\n\nHand-written history.\n'
    first = update_doc(doc, [('fess', FESS), ('maps', MAPS)], RUN)
    assert first.startswith(doc) and first.count(BEGIN) == 1 and first.rstrip().endswith(END)
    later = '2026-12-03, 2 cores, load 1.0'
    faster = [Figure('fess: track 8 x 16 map', 0.007, 's', '< 0.05 s', True)]
    second = update_doc(first + '\nA note after the table.\n', [('fess', faster)], later)
    assert second.startswith(doc) and second.endswith('\nA note after the table.\n')
    rows = existing_rows(second)
    assert rows['fess'] == [f'| fess | track 8 x 16 map | < 0.05 s | 0.007 s | yes | {later} |']
    assert rows['maps'] == [f'| maps | vectorized queries | - | 3.8e+06 1/s | - | {RUN} |']  # kept
    assert '0 goal(s) missed in this table.' in second


def test_a_named_table_replaces_only_its_own_block() -> None:
    begin, end = '<!-- benchmarks:map-accuracy:begin -->', '<!-- benchmarks:map-accuracy:end -->'
    doc = f'Prose.\n{begin}\n| old |\n{end}\nGoal text.\n'
    new = replace_named(doc, 'map-accuracy', '| new |', RUN)
    assert new == (
        'Prose.\n<!-- benchmarks:map-accuracy:begin -->\n'
        f'Measured {RUN}.\n\n| new |\n<!-- benchmarks:map-accuracy:end -->\nGoal text.\n'
    )
    assert replace_named(doc, 'other', '| new |', RUN) == doc  # no block of that name: unchanged

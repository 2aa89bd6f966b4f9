"""validate's prediction from the measured motion (``motion_prediction``) takes the first run's
joint_states rows and feeds only the odometry commands to its core (bags/validate.with_other_commands);
the reference is what it replaced: a second full estimator run over the same bag (run_estimator),
which feeds every joint_states reading through the core again."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from skidsteer_power.bag_io import open_bag
from skidsteer_power.validation.validate import (
    MEASURED_COLUMNS,
    PREDICTED_COLUMNS,
    ValidateOptions,
    build_core,
    predict_bag,
    run_estimator,
    with_other_commands,
)
from skidsteer_power.validation.validate_metrics import error_metrics

BUNDLED = Path(__file__).resolve().parents[1] / 'bags' / 'test_robot_track_sand_bin.mcap'


def test_rows_of_the_first_run_give_what_a_second_full_run_gives(tmp_path: Path) -> None:
    options = ValidateOptions('test_robot_track', 'sand_bin', tmp_path / 'report', map_cache_dir=tmp_path)
    with open_bag(BUNDLED) as bag:
        run = predict_bag(bag, options)
    assert run.motion is not None and run.inputs.js_t.size > 1000
    _, motion = run.motion
    cmd, cmd_t = motion.cmd.copy(), motion.cmd_t.copy()
    cmd[10] = (np.nan, 0.0)  # rejected by the core: the previous command stays in force
    cmd[20] = (50.0, 0.0)  # beyond the input limits: rejected too
    cmd_t[30] = run.inputs.js_t[np.searchsorted(run.inputs.js_t, cmd_t[30])]  # tie with a reading
    motion = replace(motion, cmd=cmd, cmd_t=cmd_t)

    full = run_estimator(build_core(options, kinematics='twist'), motion)
    fast = with_other_commands(build_core(options, kinematics='twist'), motion, run.series)

    assert error_metrics(fast) == error_metrics(full)
    for name in ('t_s', 'hold_s', 'cmd_fresh', *PREDICTED_COLUMNS, *MEASURED_COLUMNS):
        np.testing.assert_array_equal(fast.columns[name], full.columns[name], err_msg=name)
    fresh = fast.columns['cmd_fresh'] > 0
    assert 0 < fresh.sum() < fresh.size  # both cases occur: before the first odometry, and after it

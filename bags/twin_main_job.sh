#!/usr/bin/env bash
# The main job (make run): the estimator (FESS maps) validated against the digital twin on the
# chapter 7.3 experiment sets (Table 7.3), for the track, 4-wheel and 6-wheel test robot.
#
#   bash bags/twin_main_job.sh [OUT_DIR]        # default validation/
#
# For each configuration: the twin (skidsteer_power/twin, truth terrain sand_bin; never FESS or
# the maps) drives the sets offline and records validation/twin_<vehicle>_sand_bin.mcap; validate
# compares the estimator's predictions with it (report in validation/<vehicle>/, circle fits on
# /ground_truth/odom); validation/fess_vs_twin_<vehicle>.png plots predicted vs twin axle torque and
# power per set (Figures 7.39-7.41 style), validation/radius_cmd_vs_twin.png the radii (Figure
# 7.38 style), validation/summary.md the table. Offline rather than through the live suite: the
# twin runs faster than real time and deterministically; the live path is `run --simulate`.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-validation}
.venv/bin/python -m skidsteer_power.apps.experiment_sets "$OUT"
# Calibration (issue 15): fit the terrain to the steady segments of the bundled 4-wheel bag driven on
# clay, starting from the terrain its name claims (dry_sand): parameters with 95 % intervals, hold-out
# error before -> after, validation/calibrated_terrain.yaml and validation/calibration.png.
.venv/bin/skidsteer-power calibrate bags/test_robot_4wheel_dry_sand.mcap --vehicle test_robot_4wheel \
    --terrain dry_sand --out-terrain "$OUT/calibrated_terrain.yaml" --plot "$OUT/calibration.png"

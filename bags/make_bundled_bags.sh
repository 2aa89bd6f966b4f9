#!/usr/bin/env bash
# Make the bundled bags with the digital twin (skidsteer-power simulate): the chapter 7.3 experiment
# sets of Table 7.3 driven by each test-robot configuration on its twin's own ("truth") terrain.
# Synthetic data: no robot was measured. The twin never uses FESS or the maps (docs/TWIN.md).
#
#   bash bags/make_bundled_bags.sh              # from the project root, with .venv set up
#
# Bags (each: /cmd_vel, /joint_states, /odom, /ground_truth/odom, /battery/measured):
#   test_robot_{track,4wheel,6wheel}_sand_bin.mcap   truth sand_bin, as the name says
#   test_robot_4wheel_dry_sand.mcap                  truth CLAY, not dry_sand: validate it with
#                                                    --terrain dry_sand to see a wrong terrain
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=.venv/bin
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

# Table 7.3: 0.1 m/s at yaw rates 0-0.2 rad/s, 0.2 m/s at 0-0.35 rad/s; each set held 4 s, then 1 s
# at rest; a 2 s lead-in at rest (simulate adds 1 s more).
$BIN/python -c "
from skidsteer_power.bag_io.synthetic import Segment, table_7_3_segments, write_command_csv
write_command_csv('$WORK/table_7_3.csv', [Segment(0.0, 0.0, 2.0), *table_7_3_segments()])"

make_bag() {  # vehicle truth-terrain bag
    rm -f "bags/$3"
    echo "bags/$3: $($BIN/skidsteer-power simulate --vehicle "$1" --terrain "$2" \
        --commands "$WORK/table_7_3.csv" --seed 0 -o "bags/$3" --json | tr -d '\n' | tr -s ' ')"
}
for vehicle in test_robot_track test_robot_4wheel test_robot_6wheel; do
    make_bag "$vehicle" sand_bin "${vehicle}_sand_bin.mcap"
done
make_bag test_robot_4wheel clay test_robot_4wheel_dry_sand.mcap

#!/usr/bin/env bash
# Make the bundled bags: the project's simulated robot (skidsteer-power run --simulate) driven through
# the Table 7.3 experiment sets on the sand-bin terrain, one bag per configuration. Synthetic data.
#
#   bash bags/make_bundled_bags.sh [VEHICLE ...]   # from the project root, with .venv set up
#
# Each bag holds what the suite saw and said: /cmd_vel (the commands), /joint_states (the simulated
# DES 70/10 amplifiers: motor speed, Kt*I), /power/predicted (the power_estimator's predictions) and
# /battery/state. The simulation loads each motor with the FESS map's axle torque for the command plus
# the side's internal resistance (skidsteer_power/nodes/suite.py).
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=.venv/bin
OUT=bags
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$((RANDOM % 100 + 101))}
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST

# Table 7.3: 0.1 m/s at yaw rates 0-0.2 rad/s, 0.2 m/s at 0-0.35 rad/s; each set held 4 s, 1 s at rest.
# A 2 s lead-in at rest covers the busy suite's late DDS match of the replay's publisher.
$BIN/python -c "
from skidsteer_power.bags.synthetic import Segment, table_7_3_segments, write_drive_bag
segments = [Segment(0.0, 0.0, 2.0), *table_7_3_segments()]
write_drive_bag('$WORK/table_7_3_cmd.mcap', segments, rate_hz=20, odom_hz=None, joint_states=False)"

VEHICLES=${*:-test_robot_track test_robot_4wheel test_robot_6wheel}
for vehicle in $VEHICLES; do
    bag="$OUT/${vehicle}_sand_bin.mcap"
    rm -f "$bag"
    $BIN/skidsteer-power run --simulate --vehicle "$vehicle" --terrain sand_bin --quiet \
        --map-cache "$WORK/maps" --state-file "$WORK/energy_$vehicle.json" --duration 600 > "$WORK/run_$vehicle.log" &
    sim=$!
    sleep 8  # map build (first time) and the suite's start-up
    $BIN/skidsteer-power record -o "$bag" /cmd_vel /joint_states /power/predicted /battery/state \
        > "$WORK/record_$vehicle.json" &
    rec=$!
    $BIN/skidsteer-power replay "$WORK/table_7_3_cmd.mcap" --wait-for-subscribers 30 > /dev/null
    sleep 1
    kill -INT "$rec"; wait "$rec"
    kill -TERM "$sim"; wait "$sim" || true  # a background job ignores SIGINT in a script
    echo "$bag: $(cat "$WORK/record_$vehicle.json" | tr -d '\n' | tr -s ' ')"
done

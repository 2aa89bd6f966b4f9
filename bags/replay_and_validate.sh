#!/usr/bin/env bash
# The main job in one command: replay a bag's commands into the live node suite (simulated amplifiers),
# record what the suite publishes, validate the recording, print the summary and where the report is.
#
#   bash bags/replay_and_validate.sh [BAG] [VEHICLE] [OUT_DIR]
#   defaults: bags/test_robot_track_sand_bin.mcap test_robot_track validation/
set -euo pipefail
cd "$(dirname "$0")/.."
BAG=${1:-bags/test_robot_track_sand_bin.mcap}
VEHICLE=${2:-test_robot_track}
OUT=${3:-validation}
BIN=.venv/bin
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$((RANDOM % 100 + 101))}
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
mkdir -p "$OUT"
LIVE="$OUT/live_$(date +%Y%m%d_%H%M%S).mcap"

$BIN/skidsteer-power run --simulate --vehicle "$VEHICLE" --terrain sand_bin --quiet --duration 3600 \
    --state-file "$OUT/energy_state.json" > "$OUT/run.log" 2>&1 &
sim=$!
trap 'kill -TERM "$sim" 2>/dev/null || true' EXIT
sleep 8  # the suite's start-up (and the map build, the first time)
$BIN/skidsteer-power record -o "$LIVE" /cmd_vel /joint_states /power/predicted /battery/state \
    > "$OUT/record.log" 2>&1 &
rec=$!
# Only the commands: the simulated amplifiers produce joint_states of their own.
$BIN/skidsteer-power replay "$BAG" --topics /cmd_vel --wait-for-subscribers 30 > "$OUT/replay.log"
sleep 1
kill -INT "$rec"; wait "$rec"
$BIN/skidsteer-power validate "$LIVE" --vehicle "$VEHICLE" --terrain sand_bin --report "$OUT/report"

#!/usr/bin/env bash
# The main job in one command: replay a bag's commands into the live node suite (simulated amplifiers),
# record what the suite publishes, validate the recording, print the summary and where the report is.
#
#   bash bags/replay_and_validate.sh [BAG] [VEHICLE] [OUT_DIR] [TERRAIN]
#   defaults: bags/test_robot_track_sand_bin.mcap test_robot_track validation/ sand_bin
#
# Exit code: validate's; 1 when the suite died (run.log's last lines are shown) or the recording has
# no motor data (the estimator got no joint_states: nothing was measured).
set -euo pipefail
cd "$(dirname "$0")/.."
BAG=${1:-bags/test_robot_track_sand_bin.mcap}
VEHICLE=${2:-test_robot_track}
OUT=${3:-validation}
TERRAIN=${4:-${TERRAIN:-sand_bin}}
BIN=${BIN:-.venv/bin}
# ROS documents domain IDs 0-101 as safe on every platform (232 on Linux with care): 1-100 here
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$((RANDOM % 100 + 1))}
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
mkdir -p "$OUT"
LIVE="$OUT/live_$(date +%Y%m%d_%H%M%S).mcap"

$BIN/skidsteer-power run --simulate --vehicle "$VEHICLE" --terrain "$TERRAIN" --quiet --duration 3600 \
    --state-file "$OUT/energy_state.json" > "$OUT/run.log" 2>&1 &
sim=$!
trap 'kill -TERM "$sim" 2>/dev/null || true' EXIT
suite_alive() {
    if ! kill -0 "$sim" 2>/dev/null; then
        echo "replay_and_validate: the node suite died ($1); the end of $OUT/run.log:" >&2
        tail -n 5 "$OUT/run.log" >&2
        exit 1
    fi
}
sleep 8  # the suite's start-up (and the map build, the first time)
suite_alive 'at start-up'
$BIN/skidsteer-power record -o "$LIVE" /cmd_vel /joint_states /power/predicted /battery/state \
    > "$OUT/record.log" 2>&1 &
rec=$!
# Only the commands: the simulated amplifiers produce joint_states of their own.
$BIN/skidsteer-power replay "$BAG" --topics /cmd_vel --wait-for-subscribers 30 > "$OUT/replay.log"
sleep 1
suite_alive 'during the replay'
kill -INT "$rec"; wait "$rec"
# the live joint_states are des_driver's (motor shaft, effort = K_t I), whatever the vehicle's own stack
$BIN/skidsteer-power validate "$LIVE" --vehicle "$VEHICLE" --terrain "$TERRAIN" --report "$OUT/report" \
    --left-joints left_motor --right-joints right_motor --effort torque --joints-at motor \
    --json > "$OUT/validate.json"
$BIN/python - "$OUT/validate.json" <<'PY'
import json, sys
result = json.load(open(sys.argv[1]))
m = result['metrics']
if not result.get('has_motor_data'):
    sys.exit(f'replay_and_validate: no motor data in the live recording (the estimator measured nothing); '
             f'predicted {m["energy_predicted_J"]:.1f} J')
print(f'energy predicted {m["energy_predicted_J"]:.1f} J, measured {m["energy_measured_J"]:.1f} J, '
      f'error {m["energy_error_pct"]:.2f} %')
PY
echo "report: $OUT/report"

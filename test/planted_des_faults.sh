#!/bin/bash
# Plants each driver fault in a scratch copy of the repository (code, tests, config, benchmarks) and
# runs the check that must catch it; first, the same checks on an unmodified copy (the control) must
# PASS, so that a "catch" is the planted fault's and not a broken copy's (issue 34: every catch of
# the old script was a ConfigError, the copy lacked config/).
#   - the four faults of issue 28 and two of issue 34 (hung-poller detection removed, deactivate not
#     zeroing): the model-based safety test, three seeds (no example database, shrinking off);
#   - one fault per driver item of issue 34 (1 Ctrl-Z, 2 CRC storm, 3 slow link, 4 slow poll,
#     7 amplifier self-reset): its test in test_des_failsafe.py (item 3: its benchmark goal, a timing
#     goal that a test does not assert).
# NO_SLEW_RULE=1 also takes rule 2 out of the scratch model test, to see which rule fires then.
# Usage, from the repository root: test/planted_des_faults.sh   (about 10-15 min on 2 cores)
#   FAULTS="watchdog_removed crc_storm_unbounded" test/planted_des_faults.sh  (some faults only)
#   CONTROL=0 skips the control run. A fault whose text is not found ends the script (exit 2).
set -u
PY=${PY:-/work/main/.venv/bin/python}
SEEDS=${SEEDS:-1 2 3}
SCRATCH=$(mktemp -d)
trap 'rm -rf "$SCRATCH"' EXIT
ROOT=$PWD

copy() {  # a scratch copy of what the checks need
  local d=$SCRATCH/$1
  mkdir -p "$d" && cp -r "$ROOT"/skidsteer_power "$ROOT"/test "$ROOT"/config "$ROOT"/benchmarks "$ROOT"/pyproject.toml "$d"/
  find "$d" -name __pycache__ -prune -exec rm -rf {} +
}

plant() {  # name, file, then pairs of (old text, new text): each old text must occur exactly once
  local name=$1 file=$2
  shift 2
  copy "$name"
  "$PY" - "$SCRATCH/$name/$file" "$@" <<'PYEOF'
import sys
path, pairs = sys.argv[1], sys.argv[2:]
text = open(path).read()
for old, new in zip(pairs[::2], pairs[1::2]):
    assert text.count(old) == 1, (path, old, text.count(old))
    text = text.replace(old, new)
open(path, 'w').write(text)
PYEOF
  if [ $? -ne 0 ]; then  # the code moved: a fault not planted would be "caught" as the control's result
    echo "$name: NOT PLANTED (its text is not in $file once: update this script)"
    exit 2
  fi
  if [ "${NO_SLEW_RULE:-0}" = 1 ]; then
    sed -i 's/            if rpm != 0 and side in self.previous_reachable:  # rule 2/            if False:/' \
      "$SCRATCH/$name/test/test_des_safety_model.py"
  fi
}

# the check of each fault: model (three seeds), a pytest node id, or bench:CASES
declare -A CHECK
MODEL_FAULTS="watchdog_5x_slower watchdog_removed acceleration_limit_removed stop_both_on_link_loss_ignored hung_poller_detection_removed deactivate_not_zeroing"
for f in $MODEL_FAULTS; do CHECK[$f]=model; done
CHECK[ctrl_z_not_caught]='test/test_des_failsafe.py::test_ctrl_z_zeroes_and_disables_before_the_process_stops test/test_des_node.py::test_the_driver_catches_every_ending_signal'
CHECK[crc_storm_unbounded]='test/test_des_failsafe.py::test_crc_storm_stops_both_sides_and_the_exchange_ends'
CHECK[slow_link_no_preemption]='bench:latency16 late45'
CHECK[slow_poll_watchdog_waits]='test/test_des_failsafe.py::test_watchdog_and_deactivate_do_not_wait_for_a_slow_poll'
CHECK[self_reset_ignored]='test/test_des_failsafe.py::test_an_amplifier_reset_stops_the_other_side_and_latches'
ALL="$MODEL_FAULTS ctrl_z_not_caught crc_storm_unbounded slow_link_no_preemption slow_poll_watchdog_waits self_reset_ignored"

run_check() {  # dir, check, seed -> exit code of the check (0: passed)
  local d=$1 check=$2 seed=$3
  case $check in
    model) (cd "$d" && DES_MODEL_SHRINK=0 PYTHONPATH=$PWD timeout 900 "$PY" -m pytest -q -p no:cacheprovider \
              test/test_des_safety_model.py --hypothesis-seed="$seed" 2>&1) ;;
    bench:*) (cd "$d" && PYTHONPATH=$PWD timeout 900 "$PY" -m benchmarks.bench_des ${check#bench:} 2>&1) ;;
    *) (cd "$d" && PYTHONPATH=$PWD timeout 900 "$PY" -m pytest -q -p no:cacheprovider $check 2>&1) ;;
  esac
}

plant watchdog_5x_slower skidsteer_power/des/poller.py \
  '        if now - self._stamp > self.timeout_s:' '        if now - self._stamp > 5 * self.timeout_s:'
plant watchdog_removed skidsteer_power/des/poller.py '        if now - self._stamp > self.timeout_s:' '        if False:'
plant acceleration_limit_removed skidsteer_power/drive/controller.py \
  '        v = v0 + min(dv_max, max(-dv_max, v - v0))' '        pass'
plant stop_both_on_link_loss_ignored skidsteer_power/des/poller.py \
  '        if self.stop_both_on_link_loss and down:' '        if False and down:'
plant hung_poller_detection_removed skidsteer_power/des/poller.py \
  '            if side not in down and now - at > self.stall_timeout_s:' '            if False:'
plant deactivate_not_zeroing skidsteer_power/des/poller.py \
  $'        if not enable and self._enabled is not False:\n            self._zero_and_disable()\n' \
  $'        if not enable and self._enabled is not False:\n            self.amp.disable()\n            self._enabled = False\n'
plant ctrl_z_not_caught skidsteer_power/stop_signals.py '    for signum in STOPPING_SIGNALS:' '    for signum in ():'
plant crc_storm_unbounded skidsteer_power/des/transport.py \
  '                if repeats >= self.timing.crc_repeats or self._give_up(reply_words):' '                if False:' \
  '        deadline = min(deadline, self._deadline)' '        pass'
plant slow_link_no_preemption skidsteer_power/des/poller.py \
  $'        self._zero_now_if_due()\n        start = time.monotonic()' '        start = time.monotonic()'
plant slow_poll_watchdog_waits skidsteer_power/des/poller.py \
  '                left = min(left, self.command.stale_at() - self.clock())' '                pass'
plant self_reset_ignored skidsteer_power/des/poller.py \
  '        a brown-out): stop both sides and latch it until ~/clear_faults (issue 34 item 7)."""' \
  $'        a brown-out): stop both sides and latch it until ~/clear_faults (issue 34 item 7)."""\n        return'

status=0
FAULT_LIST=${FAULTS:-$ALL}
if [ "${CONTROL:-1}" = 1 ]; then  # the unmodified copy: every check used below must pass
  copy control
  declare -A done_check
  for fault in $FAULT_LIST; do
    check=${CHECK[$fault]}
    [ -n "${done_check[$check]:-}" ] && continue
    done_check[$check]=1
    for seed in $([ "$check" = model ] && echo $SEEDS || echo 0); do
      out=$(run_check "$SCRATCH/control" "$check" "$seed")
      if [ $? -eq 0 ]; then verdict='passes'; else verdict='FAILS (the control must pass)'; status=1; fi
      echo "control: $check${seed/#0/}$([ "$check" = model ] && echo " seed $seed"): $verdict"
      [ "$verdict" = passes ] || echo "$out" | tail -15
    done
  done
fi
for fault in $FAULT_LIST; do
  check=${CHECK[$fault]}
  for seed in $([ "$check" = model ] && echo $SEEDS || echo 0); do
    out=$(run_check "$SCRATCH/$fault" "$check" "$seed")
    if [ $? -eq 0 ]; then verdict='NOT caught'; status=1; else verdict='caught'; fi
    why=$(echo "$out" | grep -oE 'AssertionError: [A-Za-z0-9 ,._:-]+|GOAL MISSED.*|ConfigError.*' | head -1)
    echo "$fault$([ "$check" = model ] && echo " seed $seed"): $verdict ${why:0:120}"
    if echo "$out" | grep -q ConfigError; then echo "  (a ConfigError: check the scratch copy)"; fi
  done
done
exit $status

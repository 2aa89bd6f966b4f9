#!/bin/bash
# Plants each of the four driver faults of issue 28 in a scratch copy of the code and runs the
# model-based safety test on it with three seeds (no example database, shrinking off): every run
# must fail. NO_SLEW_RULE=1 also takes rule 2 out of the scratch test, to see which rule fires then.
# Usage, from the repository root: test/planted_des_faults.sh   (about 2-3 min on 2 cores)
set -u
PY=${PY:-/work/main/.venv/bin/python}
SEEDS=${SEEDS:-1 2 3}
SCRATCH=$(mktemp -d)
trap 'rm -rf "$SCRATCH"' EXIT
plant() {  # name, file, old line, new line
  local d=$SCRATCH/$1
  mkdir -p "$d" && cp -r skidsteer_power test "$d"/
  "$PY" - "$d/$2" "$3" "$4" <<'PYEOF'
import sys
path, old, new = sys.argv[1:]
text = open(path).read()
assert text.count(old) == 1, (path, old)
open(path, 'w').write(text.replace(old, new))
PYEOF
  if [ "${NO_SLEW_RULE:-0}" = 1 ]; then
    sed -i 's/            if rpm != 0 and side in self.previous_reachable:  # rule 2/            if False:/' \
      "$d/test/test_des_safety_model.py"
  fi
}
plant watchdog_5x_slower skidsteer_power/des/poller.py \
  '        if now - self._stamp > self.timeout_s:' '        if now - self._stamp > 5 * self.timeout_s:'
plant watchdog_removed skidsteer_power/des/poller.py '        if now - self._stamp > self.timeout_s:' '        if False:'
plant acceleration_limit_removed skidsteer_power/des/command.py \
  '    return value + min(max_change, max(-max_change, target - value))' '    return target'
plant stop_both_on_link_loss_ignored skidsteer_power/des/poller.py \
  '        if self.stop_both_on_link_loss and down:' '        if False and down:'
status=0
for fault in ${FAULTS:-watchdog_5x_slower watchdog_removed acceleration_limit_removed stop_both_on_link_loss_ignored}; do
  for seed in $SEEDS; do
    out=$(cd "$SCRATCH/$fault" && DES_MODEL_SHRINK=0 PYTHONPATH=$PWD timeout 900 "$PY" -m pytest -q \
      -p no:cacheprovider test/test_des_safety_model.py --hypothesis-seed="$seed" 2>&1)
    if [ $? -eq 0 ]; then verdict='NOT caught'; status=1; else verdict='caught'; fi
    echo "$fault seed $seed: $verdict $(echo "$out" | grep -oE 'AssertionError: [a-z0-9 ]+:' | head -1)"
  done
done
exit $status

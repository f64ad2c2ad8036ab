#!/usr/bin/env bash
# A speed specialist (E.T., the actions variant's seed 4): the mixed stage resumed for 40
# more epochs against a partner that moves at exactly 0.2 m/s in every episode (turning
# every 0.5 s, the motion sweep's motion), then scored on the motion sweep (64 episodes a
# speed, evaluate's seed). If training on nothing but the condition does not lift it,
# the partner distribution of the robust stages is not what holds it back. Needs the run
# folder of
#   FLAGS="--observe-recent-actions 2" LABEL=actions PARTNERS=mixed bash benchmarks/partners/seeds.sh et 4
# in runs/partners/ (RUNS overrides); archives config.json, metrics.csv, train.log and
# robustness_motion.json/.png into benchmarks/partners/motion_probe_et/specialist_0.2/ (the
# archived record ran these commands with the run folder runs/probe/et4-speed02).
set -euo pipefail
cd "$(dirname "$0")/../../.."
source benchmarks/partners/archive.sh
runs=${RUNS:-runs/partners}
out=benchmarks/partners/motion_probe_et/specialist_0.2
python=${PYTHON:-.venv/bin/python}
run=$runs/et_actions-s4-static_then_mixed_speed0.2
rm -rf "$run" && cp -rL "$runs/et_actions-s4-static_then_mixed" "$run"
nice -n 5 "$python" train.py --run-dir "$run" --resume --partners static --target-speed-range 0.2 0.2 \
  --epochs 140 --observe-recent-actions 2 > "$run.log" 2>&1
nice -n 5 "$python" -m mjx_hands.robustness "$run" --sweep motion --speeds 0 0.1 0.2 0.3 \
  --episodes 64 --out "$run-sweep" | grep '^motion:'
archive_run "$run" "$run-sweep" "$out"

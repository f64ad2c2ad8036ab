#!/usr/bin/env bash
# E.T. at a 20 ms control period (the actions variant, seed 4): does a finer control period
# hold a moving partner? The static stage (150 steps an episode, the same 3 s) trained 60
# epochs and, being at 0.33, resumed to 120; then the mixed stage to 180 (60 epochs, the
# mixed stage's 40 of 40 ms scaled by the steps it needs); both swept as
# benchmarks/partners/seeds.sh sweeps (32 episodes a condition) and scored by
# benchmarks.contact_hold --gaps at 64 episodes a speed. The archived record ran these
# commands with the run folders runs/probe/et4-dt20-*.
set -euo pipefail
cd "$(dirname "$0")/../../../.."
source benchmarks/partners/archive.sh
python=${PYTHON:-.venv/bin/python}
run=${RUNS:-runs/probe}/et4-dt20
out=benchmarks/partners/motion_probe_et/control_20ms
flags=(--observe-recent-actions 2)
nice -n 5 "$python" train.py --task et --mocap-source optitrack --control-dt 0.02 --episode-length 150 \
  --epochs 60 --seed 4 "${flags[@]}" --run-dir "$run-static" > "$run-static.log" 2>&1
nice -n 5 "$python" train.py --run-dir "$run-static" --resume --epochs 120 "${flags[@]}" >> "$run-static.log" 2>&1
rm -rf "$run-static_then_mixed" && cp -rL "$run-static" "$run-static_then_mixed"
nice -n 5 "$python" train.py --run-dir "$run-static_then_mixed" --resume --partners mixed --epochs 180 \
  "${flags[@]}" > "$run-static_then_mixed.log" 2>&1
for stage in static static_then_mixed; do
  nice -n 5 "$python" -m mjx_hands.robustness "$run-$stage" --sweep all --episodes 32 --out "$run-$stage-sweeps"
  archive_run "$run-$stage" "$run-$stage-sweeps" "$out/$stage"
done
nice -n 5 "$python" -m benchmarks.contact_hold dt20_static="$run-static" dt20_mixed="$run-static_then_mixed" \
  --speeds 0 0.1 0.2 0.3 --episodes 64 --gaps --out "$out/contact_gaps.json"
relative_paths "$out"

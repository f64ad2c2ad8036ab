#!/usr/bin/env bash
# How far a longer mixed stage carries the clap's turned partner (seed 1): its 160-epoch
# mixed stage (the 100 mixed epochs of
#   PARTNERS=mixed STAGE_FLAGS="--epochs 160" STAGE_LABEL=long bash benchmarks/partners/seeds.sh handclap 1
# archived in benchmarks/partners/handclap/seed1/static_then_mixed_long/) resumed with the
# same partners to 240 epochs, then swept and scored as every seed is (32 episodes a
# condition, naturalness over 64). Needs that stage's run folder in runs/partners/ (RUNS
# overrides); archives config.json, metrics.csv, train.log and the sweeps into
# benchmarks/partners/clap_long/static_then_mixed_240/.
set -euo pipefail
cd "$(dirname "$0")/../../.."
source benchmarks/partners/archive.sh
runs=${RUNS:-runs/partners}
out=benchmarks/partners/clap_long/static_then_mixed_240
python=${PYTHON:-.venv/bin/python}
run=$runs/handclap-s1-static_then_mixed_240
rm -rf "$run" "$run-sweep" && cp -rL "$runs/handclap-s1-static_then_mixed_long" "$run"
nice -n 10 "$python" train.py --run-dir "$run" --resume --partners mixed --epochs 240 > "$run.log" 2>&1
nice -n 10 "$python" -m mjx_hands.robustness "$run" --sweep all --episodes 32 --out "$run-sweep" \
  > "$run-sweep.log" 2>&1
nice -n 10 "$python" -m mjx_hands.naturalness "$run" --episodes 64 --out "$run-sweep" >> "$run-sweep.log" 2>&1
archive_run "$run" "$run-sweep" "$out"

#!/usr/bin/env bash
# What makes a moving partner hard (E.T., the actions variant's seed 4): its jump of
# speed x control_dt before each period's substeps, or its turns? One policy trained
# against per-step partners, scored under both partner motions and four turn periods
# (64 episodes a speed, evaluate's seed). Needs the run folders of
#   FLAGS="--observe-recent-actions 2" LABEL=actions PARTNERS=mixed bash benchmarks/partners/seeds.sh et 4
# in runs/partners/ (RUNS overrides), and writes robustness_motion.json per case here.
set -euo pipefail
cd "$(dirname "$0")/../../.."
runs=${RUNS:-runs/partners}
out=benchmarks/partners/motion_probe_et
python=${PYTHON:-.venv/bin/python}
sweep() {  # name run [robustness options...]
  local name=$1 run=$2; shift 2
  nice -n 10 "$python" -m mjx_hands.robustness "$runs/$run" --sweep motion --episodes 64 \
    --out "$out/$name" "$@" | grep '^motion:'
  rm -f "$out/$name"/*.png
}
for stage in static static_then_mixed; do
  for motion in per_step continuous; do
    sweep "$stage-$motion" "et_actions-s4-$stage" --speeds 0 0.1 0.2 0.3 --partner-motion "$motion"
  done
done
for period in 0.25 1 2 8; do
  sweep "static_then_mixed-turns-$period" et_actions-s4-static_then_mixed --speeds 0.2 --turn-period "$period"
done

#!/usr/bin/env bash
# The physics oracle's records (benchmarks.contact_oracle): trains the three static
# policies whose rest contacts it starts from (E.T.: the actions variant's seed 4; the
# clap's seed 0; the handshake's seed 4; 60 epochs each, authors' recordings), then
# measures the oracle beside each policy on the motion sweep's episodes and writes the
# JSON records here. About 70 min on 2 cores. RUNS overrides the run folders' parent.
set -euo pipefail
cd "$(dirname "$0")/../../.."
runs=${RUNS:-runs/oracle}
out=benchmarks/partners/contact_oracle
python=${PYTHON:-.venv/bin/python}
mkdir -p "$runs"
train() {  # RUN_NAME TRAIN.PY-FLAGS...
  local run=$runs/$1; shift
  [ -f "$run/config.json" ] || nice -n 5 "$python" train.py --mocap-source optitrack --epochs 60 \
    --run-dir "$run" "$@" > "$run.log" 2>&1
}
oracle() {  # RUN_NAME RECORD ORACLE-FLAGS...
  local run=$runs/$1 record=$2; shift 2
  PYTHONPATH=. nice -n 5 "$python" -m benchmarks.contact_oracle "$run" --out "$out/$record.json" "$@"
}
train et-actions-s4-static --task et --seed 4 --observe-recent-actions 2
train handclap-s0-static --task handclap --seed 0
train handshake-s4-static --task handshake --seed 4
oracle et-actions-s4-static et --speeds 0 0.1 0.2 0.3 --episodes 32
oracle et-actions-s4-static et_64 --speeds 0.2 --episodes 64
oracle et-actions-s4-static et_contact_weight10_64 --speeds 0.2 --episodes 64 --contact-weight 10
oracle et-actions-s4-static et_joints --speeds 0 0.2 --episodes 32 --aim joints
oracle et-actions-s4-static et_press4 --speeds 0.2 --episodes 32 --press-mm 4
oracle et-actions-s4-static et_turn8 --speeds 0.2 --episodes 32 --turn-period 8
oracle handclap-s0-static handclap --speeds 0 0.1 0.2 0.3 --episodes 32
oracle handshake-s4-static handshake --speeds 0 0.1 0.2 0.3 --episodes 32

#!/usr/bin/env bash
# Static-trained against static-then-robust policies, one seed at a time, each archived as
# it ends (the partner targets' 5 seeds per task, a few per session).
#
#   nohup bash benchmarks/partners/seeds.sh et 1 2 &      # E.T., seeds 1 and 2
#
# Per seed, on the authors' recordings (it fails without them), with the committed code
# (a `git archive` of HEAD, as benchmarks/paper/chunks.sh), niced:
#   1. static: train.py --epochs 60 (384 k env steps on E.T. and the clap);
#   2. static then robust: a copy of 1 resumed with --partners robust to 100 epochs
#      (PARTNERS=mixed: --partners mixed, archived as static_then_mixed);
#   3. every robustness sweep (32 episodes a condition, scored against the static partner)
#      and the naturalness metrics (64 episodes) of both policies.
# Archived into benchmarks/partners/<task>/seed<k>/{static,static_then_robust}/ and named
# in runs/partners/status. A seed already archived is skipped, unless it lacks the
# PARTNERS stage and its static run is still in the runs folder: then only that stage is
# trained, swept and archived beside the others (PARTNERS=mixed bash ... et 1 2).
# `python -m benchmarks.regenerate` pools the seeds into the
# side-by-side table (benchmarks/partners/<task>/side_by_side.md). RUNS overrides the
# folder of the run directories. FLAGS adds train.py flags to both stages (e.g. an
# observation setting both must share) and LABEL names the variant, archived into
# benchmarks/partners/<task>_<LABEL>/:
#
#   FLAGS=--observe-target-velocity LABEL=velocity nohup bash benchmarks/partners/seeds.sh handclap 0 &
#
# STAGE_FLAGS adds flags to the second stage only and STAGE_LABEL names that stage's
# folder (static_then_<PARTNERS>_<STAGE_LABEL>), beside the seed's other stages:
#
#   PARTNERS=mixed STAGE_FLAGS="--action-rate-weight 0.05" STAGE_LABEL=smooth \
#       nohup bash benchmarks/partners/seeds.sh handclap 0 &
#
# A new stage of an archived seed whose static run is gone (a fresh machine) retrains the
# static run with the same command and goes on only if its evaluations reproduce the
# archived static run's metrics.csv, so the new stage starts where the archived ones did.
# A finished static run already in the runs folder (e.g. a retrained one moved to a
# LABEL's name) is used as it is, not trained again.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
source benchmarks/partners/archive.sh
task=${1:?usage: bash benchmarks/partners/seeds.sh TASK SEED...}
shift
[ $# -gt 0 ] || { echo "usage: bash benchmarks/partners/seeds.sh TASK SEED... (no seed given)" >&2; exit 2; }
runs=${RUNS:-$root/runs/partners}
mkdir -p "$runs"
snap=$(mktemp -d "$root/../.mjx-hands-partners-code-XXXX")
trap 'rm -rf "$snap"' EXIT
git archive HEAD | tar -x -C "$snap"
python=${PYTHON:-$root/.venv/bin/python}
read -ra flags <<< "${FLAGS:-}"
read -ra stage_flags <<< "${STAGE_FLAGS:-}"
partners=${PARTNERS:-robust}
case $partners in robust|mixed) ;; *) echo "PARTNERS=$partners: expected robust or mixed" >&2; exit 2;; esac
variant=${LABEL:+_$LABEL}
stage_name=static_then_$partners${STAGE_LABEL:+_$STAGE_LABEL}
run() { (cd "$snap" && nice -n 10 "$python" "$@"); }

finished_static() {  # whether $runs/$name-static holds a finished 60-epoch static run
  [ -f "$runs/$name-static/config.json" ] && [ -f "$runs/$name-static/metrics.csv" ] &&
    tail -n 1 "$runs/$name-static/metrics.csv" | grep -q '^60\.0,'
}

train_static() {  # seed $1's static stage into $runs/$name-static (a finished one is kept)
  if finished_static; then echo "$name: static run kept" >> "$runs/status"; return 0; fi
  rm -rf "$runs/$name-static"
  run train.py --task "$task" --mocap-source optitrack --epochs 60 --seed "$1" "${flags[@]}" \
    --run-dir "$runs/$name-static" > "$runs/$name-static.log" 2>&1
}

second_stage() {  # seed's static run, resumed against the $partners models
  local curriculum=$runs/$name-$stage_name
  rm -rf "$curriculum" && cp -rL "$runs/$name-static" "$curriculum" || return 1  # -L: linked runs
  run train.py --run-dir "$curriculum" --resume --partners "$partners" --epochs 100 "${flags[@]}" \
    "${stage_flags[@]}" > "$curriculum.log" 2>&1
}

same_evaluations() {  # whether metrics.csv $1 and $2 hold the same evaluations, epoch by epoch
  "$python" - "$1" "$2" <<'PY'
import csv, sys
def evals(path):
    with open(path) as f:
        return [{k: v for k, v in row.items() if k == "epoch" or k.startswith("eval/")}
                for row in csv.DictReader(f) if row.get("eval/success")]
a, b = evals(sys.argv[1]), evals(sys.argv[2])
if a != b:
    sys.exit(f"{sys.argv[1]}: its evaluations differ from {sys.argv[2]}'s")
PY
}

sweep_into() {  # sweep setup $1 of this seed and archive its record into folder $2
  local setup=$1 out=$runs/$name-sweeps/$1
  mkdir -p "$runs/$name-sweeps"
  run -m mjx_hands.robustness "$runs/$name-$setup" --sweep all --episodes 32 --out "$out" \
    > "$out.log" 2>&1 || return 1
  run -m mjx_hands.naturalness "$runs/$name-$setup" --episodes 64 --out "$out" \
    >> "$out.log" 2>&1 || return 1
  [ -f "$out/naturalness.json" ] || return 1
  ROOT=$root archive_run "$runs/$name-$setup" "$out" "$2"
}

one_seed() {  # train, sweep and archive seed $1 into $dest.tmp; fails at its first error
  local seed=$1
  rm -rf "$runs/$name-sweeps" "$dest.tmp"
  train_static "$seed" || return 1
  second_stage || return 1
  for setup in static "$stage_name"; do
    sweep_into "$setup" "$dest.tmp/$setup" || return 1
  done
}

archive() {  # $1: what finished into folder $2 (or not, status $3)
  if [ "$3" = 0 ]; then
    mv "$2.tmp" "$2"
    echo "$name: $1 done $(date -u +%FT%TZ), archived in $2" >> "$runs/status"
  else
    rm -rf "$2.tmp"
    echo "$name: $1 failed $(date -u +%FT%TZ), see $runs/$name-*.log" >> "$runs/status"
  fi
}

for seed in "$@"; do
  name=$task$variant-s$seed
  dest=$root/benchmarks/partners/$task$variant/seed$seed
  stage=$dest/$stage_name
  if [ ! -e "$dest" ]; then  # a seed is archived whole or not at all
    if one_seed "$seed"; then archive "seed $seed" "$dest" 0; else archive "seed $seed" "$dest" 1; fi
  elif [ ! -e "$stage" ]; then  # an archived seed: only the second stage is new
    if [ ! -d "$runs/$name-static" ]; then  # gone with its machine: retrain, as archived
      if ! { train_static "$seed" && same_evaluations "$runs/$name-static/metrics.csv" \
               "$dest/static/metrics.csv" 2>> "$runs/$name-static.log"; }; then
        archive "$stage_name stage of seed $seed (static run retrained)" "$stage" 1
        continue
      fi
    fi
    if second_stage && sweep_into "$stage_name" "$stage.tmp"; then
      archive "$stage_name stage of seed $seed" "$stage" 0
    else
      archive "$stage_name stage of seed $seed" "$stage" 1
    fi
  else
    echo "$name: $dest exists, skipped" >> "$runs/status"
  fi
done

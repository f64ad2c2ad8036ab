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
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
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
partners=${PARTNERS:-robust}
case $partners in robust|mixed) ;; *) echo "PARTNERS=$partners: expected robust or mixed" >&2; exit 2;; esac
variant=${LABEL:+_$LABEL}
run() { (cd "$snap" && nice -n 10 "$python" "$@"); }

second_stage() {  # seed's static run, resumed against the $partners models
  local curriculum=$runs/$name-static_then_$partners
  rm -rf "$curriculum" && cp -rL "$runs/$name-static" "$curriculum" || return 1  # -L: linked runs
  run train.py --run-dir "$curriculum" --resume --partners "$partners" --epochs 100 "${flags[@]}" \
    > "$curriculum.log" 2>&1
}

sweep_into() {  # sweep setup $1 of this seed and copy its record into folder $2
  local setup=$1 out=$runs/$name-sweeps/$1
  mkdir -p "$runs/$name-sweeps" "$2"
  run -m mjx_hands.robustness "$runs/$name-$setup" --sweep all --episodes 32 --out "$out" \
    > "$out.log" 2>&1 || return 1
  run -m mjx_hands.naturalness "$runs/$name-$setup" --episodes 64 --out "$out" \
    >> "$out.log" 2>&1 || return 1
  cp "$runs/$name-$setup"/{config.json,metrics.csv} "$out"/robustness_*.{json,png} \
    "$out/naturalness.json" "$2/" || return 1
  cp "$runs/$name-$setup.log" "$2/train.log" || return 1
  # Paths relative to the checkout (text files only; none to rewrite is fine).
  { grep -rlI "$root/" "$2" || true; } | xargs -r sed -i "s#$root/##g"
}

one_seed() {  # train, sweep and archive seed $1 into $dest.tmp; fails at its first error
  local seed=$1 static=$runs/$name-static
  rm -rf "$static" "$runs/$name-sweeps" "$dest.tmp"
  run train.py --task "$task" --mocap-source optitrack --epochs 60 --seed "$seed" "${flags[@]}" \
    --run-dir "$static" > "$static.log" 2>&1 || return 1
  second_stage || return 1
  for setup in static "static_then_$partners"; do
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
  stage=$dest/static_then_$partners
  if [ ! -e "$dest" ]; then  # a seed is archived whole or not at all
    if one_seed "$seed"; then archive "seed $seed" "$dest" 0; else archive "seed $seed" "$dest" 1; fi
  elif [ ! -e "$stage" ] && [ -d "$runs/$name-static" ]; then
    # An archived seed whose static run is still here: only the second stage is new.
    if second_stage && sweep_into "static_then_$partners" "$stage.tmp"; then
      archive "$partners stage of seed $seed" "$stage" 0
    else
      archive "$partners stage of seed $seed" "$stage" 1
    fi
  else
    echo "$name: $dest exists, skipped" >> "$runs/status"
  fi
done

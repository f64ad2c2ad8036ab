#!/usr/bin/env bash
# Static-trained against static-then-robust policies, one seed at a time, each archived as
# it ends (the partner targets' 5 seeds per task, a few per session).
#
#   nohup bash benchmarks/partners/seeds.sh et 1 2 &      # E.T., seeds 1 and 2
#
# Per seed, on the authors' recordings (it fails without them), with the committed code
# (a `git archive` of HEAD, as benchmarks/paper/chunks.sh), niced:
#   1. static: train.py --epochs 60 (384 k env steps on E.T. and the clap);
#   2. static then robust: a copy of 1 resumed with --partners robust to 100 epochs;
#   3. every robustness sweep (32 episodes a condition, scored against the static partner)
#      and the naturalness metrics (64 episodes) of both policies.
# Archived into benchmarks/partners/<task>/seed<k>/{static,static_then_robust}/ and named
# in runs/partners/status; `python -m benchmarks.regenerate` pools the seeds into the
# side-by-side table (benchmarks/partners/<task>/side_by_side.md). RUNS overrides the
# folder of the run directories.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
task=$1
shift
runs=${RUNS:-$root/runs/partners}
mkdir -p "$runs"
snap=$(mktemp -d "$root/../.mjx-hands-partners-code-XXXX")
git archive HEAD | tar -x -C "$snap"
python=${PYTHON:-$root/.venv/bin/python}
run() { (cd "$snap" && nice -n 10 "$python" "$@"); }
for seed in "$@"; do
  name=$task-s$seed
  dest=$root/benchmarks/partners/$task/seed$seed
  if [ -e "$dest" ]; then echo "$name: $dest exists, skipped" >> "$runs/status"; continue; fi
  static=$runs/$name-static curriculum=$runs/$name-static_then_robust
  rm -rf "$static" "$curriculum" "$runs/$name-sweeps"
  mkdir -p "$runs/$name-sweeps"
  if run train.py --task "$task" --mocap-source optitrack --epochs 60 --seed "$seed" \
        --run-dir "$static" > "$static.log" 2>&1 \
     && cp -r "$static" "$curriculum" \
     && run train.py --run-dir "$curriculum" --resume --partners robust --epochs 100 \
        > "$curriculum.log" 2>&1; then
    for setup in static static_then_robust; do
      out=$runs/$name-sweeps/$setup
      run -m mjx_hands.robustness "$runs/$name-$setup" --sweep all --episodes 32 --out "$out" \
        > "$out.log" 2>&1
      run -m mjx_hands.naturalness "$runs/$name-$setup" --episodes 64 --out "$out" \
        >> "$out.log" 2>&1
      mkdir -p "$dest/$setup"
      cp "$runs/$name-$setup"/{config.json,metrics.csv} "$out"/robustness_*.{json,png} \
        "$out/naturalness.json" "$dest/$setup/"
      cp "$runs/$name-$setup.log" "$dest/$setup/train.log"
    done
    grep -rl "$root/" "$dest" | xargs -r sed -i "s#$root/##g"  # paths relative to the checkout
    echo "$name: done $(date -u +%FT%TZ), archived in $dest" >> "$runs/status"
  else
    echo "$name: failed $(date -u +%FT%TZ), see $runs/$name-*.log" >> "$runs/status"
  fi
done
rm -rf "$snap"

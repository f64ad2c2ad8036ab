#!/usr/bin/env bash
# Train chunks of the Fig. 4 grids one after another and archive each as it ends.
#
#   nohup bash benchmarks/paper/chunks.sh paper et 1 2 &       # paper profile, E.T., seeds 1, 2
#   nohup bash benchmarks/paper/chunks.sh project handshake 0 &  # project profile beside it
#
# A chunk is one seed of every variant of one task (README.md here), on the authors'
# recordings (it fails without them). It runs the committed code (a `git archive` of
# HEAD beside the checkout, where ../shared is found as from it, so edits to the working
# tree during the hours a chunk takes change nothing), niced; a finished chunk is
# archived into benchmarks/paper/<profile>/<task>/seed<k>/ and named in
# runs/chunks/status. RUNS overrides the folder of the run directories.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
profile=$1 task=$2
shift 2
runs=${RUNS:-$root/runs/chunks}
mkdir -p "$runs"
snap=$(mktemp -d "$root/../.mjx-hands-chunk-code-XXXX")
git archive HEAD | tar -x -C "$snap"
python=${PYTHON:-$root/.venv/bin/python}
length=$([ "$task" = handshake ] && echo 20 || echo 15)  # iterations of the authors' epoch
for seed in "$@"; do
  name=$profile-$task-s$seed
  dest=$root/benchmarks/paper/$profile/$task/seed$seed
  if [ -e "$dest" ]; then echo "$name: $dest exists, skipped" >> "$runs/status"; continue; fi
  if [ "$profile" = paper ]; then
    args=(--profile paper)
  else  # ddpg-ln and the project's env, at the authors' budget and evaluation points
    args=(--variants full no_imitation --num-envs 50 --ddpg.unroll-length 10
          --ddpg.iterations-per-epoch "$length" --replay-ratio 25.6 --epochs 50 --eval-every 5)
  fi
  rm -rf "${runs:?}/$name"
  if (cd "$snap" && nice -n 10 "$python" -m mjx_hands.experiments run --task "$task" \
        --seed "$seed" --seeds 1 --mocap-source optitrack --no-save-replay --run-dir "$runs/$name" "${args[@]}") \
        > "$runs/$name.log" 2>&1; then
    (cd "$snap" && "$python" -m mjx_hands.experiments archive "$runs/$name" "$dest" \
        --log "$runs/$name.log")
    { grep -rlI "$root/" "$dest" || true; } | xargs -r sed -i "s#$root/##g"  # paths relative to the checkout
    echo "$name: done $(date -u +%FT%TZ), archived in $dest" >> "$runs/status"
  else
    echo "$name: failed $(date -u +%FT%TZ), see $runs/$name.log" >> "$runs/status"
  fi
done
rm -rf "$snap"

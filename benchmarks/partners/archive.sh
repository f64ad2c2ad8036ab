# Sourced by the partner scripts: how a trained and swept run becomes a committed record.

# archive_run RUN SWEEPS OUT: RUN's config.json and metrics.csv, SWEEPS' robustness_*.json
# and .png (and naturalness.json, where swept) and RUN.log as train.log, into OUT, with
# the checkout's paths made relative (ROOT, default the working directory).
archive_run() {
  local run=$1 sweeps=$2 out=$3
  mkdir -p "$out" || return 1
  cp "$run"/{config.json,metrics.csv} "$sweeps"/robustness_*.{json,png} "$out/" || return 1
  if [ -f "$sweeps/naturalness.json" ]; then cp "$sweeps/naturalness.json" "$out/" || return 1; fi
  cp "$run.log" "$out/train.log" || return 1
  relative_paths "$out"
}

# relative_paths DIR: the checkout's paths (ROOT, default the working directory) in DIR's
# text files made relative to it (none to rewrite is fine).
relative_paths() {
  local root=${ROOT:-$(pwd)}
  { grep -rlI "$root/" "$1" || true; } | xargs -r sed -i "s#$root/##g"
}

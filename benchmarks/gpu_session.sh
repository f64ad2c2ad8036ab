#!/usr/bin/env bash
# One GPU session in a fixed wall-clock budget: the MJX-vs-native throughput sweep,
# then a handshake DDPG run with the GPU preset. Everything worth keeping lands in
# $OUT (default ./gpu_out): throughput JSON, logs, the run's metrics, config and plot.
#
#   BUDGET_S=560 bash benchmarks/gpu_session.sh
#   STAGES=train BUDGET_S=480 bash benchmarks/gpu_session.sh   # training only
#   STAGES=grid BUDGET_S=560 bash benchmarks/gpu_session.sh    # the Fig. 4 grid, 3 tasks
#   STAGES=learners BUDGET_S=560 bash benchmarks/gpu_session.sh  # DDPG, LayerNorm, td3: 5 seeds each
#   STAGES=target BUDGET_S=560 bash benchmarks/gpu_session.sh    # handshake: minutes to 90 % from launch
#   STAGES=paper BUDGET_S=560 bash benchmarks/gpu_session.sh     # --profile paper Fig. 4, 5 seeds
#   LEARNERS="ddpg nstep3 twin layernorm smoothing delay c51 td3" STAGES=learners ...  # each option
#   STAGES=physics BUDGET_S=560 bash benchmarks/gpu_session.sh   # MJX, Warp, native: time, train, transfer
#
# STAGES (default "throughput train") picks the stages and their order; training gets
# whatever of BUDGET_S the stages before it left.
#
#   DRY_RUN=1 STAGES="throughput train grid learners target paper physics" bash benchmarks/gpu_session.sh
#
# runs every stage at tiny sizes on any machine (CPU included) to the same files: CI does,
# so the script cannot rot between GPU sessions.
# On a machine that has JAX (with CUDA) but not mujoco/mujoco-mjx/brax, put their
# wheels in .whl/ first (see benchmarks/RESULTS.md, "Running on a GPU").
set -u
OUT=${OUT:-gpu_out}
DRY_RUN=${DRY_RUN:-0}
# A dry run on 2 CPU cores compiles MJX for the throughput stage (minutes): more time.
BUDGET_S=${BUDGET_S:-$([ "$DRY_RUN" = 1 ] && echo 3600 || echo 560)}
THROUGHPUT_S=${THROUGHPUT_S:-$([ "$DRY_RUN" = 1 ] && echo 900 || echo 200)}
mkdir -p "$OUT"
WHEELS=${WHEELS:-.whl}
STAGES=${STAGES:-throughput train}
TINY=""  # appended to every training command (the last of a repeated flag wins)
if [ "$DRY_RUN" = 1 ]; then
  TINY="--mocap-source synthetic --num-envs 4 --eval-envs 4 --epochs 1 --eval-every 1
    --ddpg.batch-size 16 --ddpg.replay-capacity 256 --ddpg.min-replay-size 16
    --ddpg.unroll-length 2 --ddpg.iterations-per-epoch 1 --ddpg.updates-per-iteration 2
    --ddpg.hidden-sizes 16 16"
  BATCHES=${BATCHES:-4} ENV_STEP_BATCHES=${ENV_STEP_BATCHES:-4} CONTROL_STEPS=${CONTROL_STEPS:-2}
  PHYSICS_BATCH=${PHYSICS_BATCH:-4}
  GRID_SEEDS=${GRID_SEEDS:-1} PAPER_SEEDS=${PAPER_SEEDS:-1} GRID_TASKS=${GRID_TASKS:-et}
  PAPER_TASKS=${PAPER_TASKS:-et} LEARNER_SEEDS=${LEARNER_SEEDS:-1} TIME_MINUTES=0.5
fi
# A warm machine keeps /tmp/site from an earlier call: install once.
if compgen -G "$WHEELS/*.whl" >/dev/null && [ ! -d /tmp/site/mujoco ]; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site "$WHEELS"/*.whl || exit 1
  # Package data carried without its package (e.g. only the Shadow hand assets).
  if [ -d "$WHEELS/site" ]; then cp -r "$WHEELS"/site/* /tmp/site/; fi
fi
if [ -d /tmp/site/mujoco ]; then export PYTHONPATH=/tmp/site; fi
# No rendering here; EGL may be absent, and mujoco only tolerates an ImportError from it.
export PYTHONUNBUFFERED=1 MUJOCO_GL=${MUJOCO_GL:-glfw}
export XLA_FLAGS="${XLA_FLAGS:-} --xla_gpu_triton_gemm_any=true"

{
  date -u
  nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv 2>/dev/null
  python3 -m benchmarks.machine  # devices, XLA flags as training sees them, versions
} 2>&1 | tee "$OUT/session.log"

throughput() {
  echo "== throughput sweep (at most ${THROUGHPUT_S} s)" | tee -a "$OUT/session.log"
  timeout "$THROUGHPUT_S" python3 -m benchmarks.throughput \
    --batch-sizes "${BATCHES:-256,4096,16384}" --env-step-batches "${ENV_STEP_BATCHES:-4096}" \
    --control-steps "${CONTROL_STEPS:-20}" --out "$OUT/results_gpu.json" 2>&1 | tee "$OUT/throughput.log"
}

train() {
  # Training gets what is left; train.py's --max-minutes counts from after its init
  # compile, so keep a minute back for that and the final evaluation.
  left=$((BUDGET_S - SECONDS))
  minutes=$(python3 -c "print(max(0.5, ($left - 90) / 60))")
  echo "== training: ${left} s left, --max-minutes ${minutes}" | tee -a "$OUT/session.log"
  rm -rf /tmp/gpu_run
  # shellcheck disable=SC2086  # TRAIN_ARGS and TINY hold several flags
  timeout -s INT "$((left - 10))" python3 train.py --task handshake --mocap-source synthetic --preset gpu \
    --max-minutes "$minutes" --run-dir /tmp/gpu_run ${TRAIN_ARGS:-} $TINY 2>&1 | tee "$OUT/train.log"
  for f in metrics.csv success.png config.json; do cp "/tmp/gpu_run/$f" "$OUT/" 2>/dev/null; done
}

warp_ready() {
  python3 -c "import warp" 2>/dev/null || {
    echo "   MuJoCo Warp is not installed (pip install -e '.[warp]', or warp-lang's wheel in $WHEELS): skipped" | tee -a "$OUT/session.log"
    return 1
  }
}

physics() {
  # The three physics behind the one environment: env.step throughput side by side at one
  # batch, then the handshake trained on each with an equal share of what is left.
  echo "== physics: MJX, MuJoCo Warp and native side by side" | tee -a "$OUT/session.log"
  warp=""; impls="mjx native"
  if warp_ready; then warp="--warp"; impls="mjx warp native"; fi
  # shellcheck disable=SC2086  # $warp is one flag or none
  timeout "$THROUGHPUT_S" python3 -m benchmarks.throughput --batch-sizes "${PHYSICS_BATCH:-4096}" \
    --control-steps "${CONTROL_STEPS:-20}" $warp --out "$OUT/results_physics.json" 2>&1 | tee "$OUT/physics_throughput.log"
  trained=0; count=$(wc -w <<< "$impls"); done_count=0
  for impl in $impls; do
    # 150 s kept for scoring the policies on both physics after training.
    share=$(((BUDGET_S - SECONDS - 150) / (count - done_count))); done_count=$((done_count + 1))
    if [ "$share" -lt 120 ]; then
      echo "== physics: ${share} s left for $impl, too little to train: skipped" | tee -a "$OUT/session.log"
      continue
    fi
    minutes=$(python3 -c "print(max(0.5, ($share - 90) / 60))")
    echo "== physics: training on $impl, --max-minutes $minutes" | tee -a "$OUT/session.log"
    rm -rf "/tmp/gpu_run_$impl"; mkdir -p "$OUT/physics/$impl"
    # shellcheck disable=SC2086  # TINY holds several flags
    # Contacts push from touching on (force margin 0), where MJX and native agree, so the
    # policies can be moved between the physics below (physics_agreement.md).
    timeout -s INT "$((share - 10))" python3 train.py --task handshake --mocap-source synthetic --preset gpu \
      --physics "$impl" --scene.force-margin "${FORCE_MARGIN:-0}" --max-minutes "$minutes" \
      --run-dir "/tmp/gpu_run_$impl" $TINY 2>&1 | tee "$OUT/physics/$impl/train.log"
    for f in metrics.csv success.png config.json; do cp "/tmp/gpu_run_$impl/$f" "$OUT/physics/$impl/" 2>/dev/null; done
    [ -e "$OUT/physics/$impl/metrics.csv" ] && trained=$((trained + 1))
  done
  # Every trained policy on native MuJoCo and on MJX (transfer both ways, same episodes).
  runs=$(for impl in $impls; do [ -e "/tmp/gpu_run_$impl/config.json" ] && echo "/tmp/gpu_run_$impl"; done)
  # shellcheck disable=SC2086  # $runs holds several folders
  [ -n "$runs" ] && python3 -m benchmarks.physics_transfer $runs --physics native mjx \
    --episodes "${TRANSFER_EPISODES:-$([ "$DRY_RUN" = 1 ] && echo 4 || echo 128)}" \
    --out "$OUT/physics/transfer.json" 2>&1 | tee "$OUT/physics/transfer.log"
  # The stage's result: every implementation trained (a dry run fails otherwise).
  [ "$trained" = "$count" ] && [ -e "$OUT/physics/transfer.json" ] && echo "$impls" > "$OUT/physics/trained"
}

grids_by_task() {
  # Usage: grids_by_task LABEL "TASKS" REPORT_DIR [experiments run flags...]
  # Per task one population (one program), the tasks one after another in equal shares
  # of what is left; each grid's files but checkpoints land in $OUT; then the report.
  label=$1 tasks=$2 report=$3
  shift 3
  n=$(echo $tasks | wc -w)
  for task in $tasks; do
    left=$((BUDGET_S - SECONDS))
    minutes=$(python3 -c "print(max(0.5, ($left / $n - 120) / 60))")
    n=$((n - 1 > 0 ? n - 1 : 1))
    echo "== $label $task: ${left} s left, --max-minutes ${minutes}" | tee -a "$OUT/session.log"
    rm -rf "/tmp/$label-$task"
    # shellcheck disable=SC2086  # TINY holds several flags
    timeout -s INT "$((left - 10))" python3 -m mjx_hands.experiments run --task "$task" "$@" \
      --max-minutes "$minutes" --run-dir "/tmp/$label-$task" $TINY 2>&1 | tee "$OUT/$label-$task.log"
    # Everything but checkpoints: metrics, configs, plots of every member.
    (cd /tmp && find "$label-$task" -name checkpoints -prune -o -name best -prune -o -type f -print \
      | tar -cf - -T -) | tar -xf - -C "$OUT"
  done
  python3 -m mjx_hands.experiments report $(for t in $tasks; do echo "$OUT/$label-$t"; done) \
    --out "$OUT/$report" 2>&1 | tee "$OUT/$report.log"
}

grid() {
  # The paper's Fig. 4 grid with the project's setup on the GPU preset.
  # shellcheck disable=SC2086  # GRID_ARGS holds several flags
  grids_by_task grid "${GRID_TASKS:-handshake handclap et}" fig4 \
    --preset gpu --seeds "${GRID_SEEDS:-5}" --num-envs "${GRID_ENVS:-1024}" --eval-envs 256 \
    --ddpg.batch-size 1024 --ddpg.replay-capacity 250000 --ddpg.min-replay-size 10240 \
    --no-save-replay --epochs 1000 ${GRID_ARGS:-}
}

paper() {
  # The paper profile's Fig. 4 at the authors' budget (50 epochs of 50 cycles): 4 variants
  # x 5 seeds per task; the report judges the statements per profile, with Holm's correction.
  # shellcheck disable=SC2086  # PAPER_ARGS holds several flags
  grids_by_task paper "${PAPER_TASKS:-et handclap handshake}" paper-fig4 \
    --profile paper --seeds "${PAPER_SEEDS:-5}" --no-save-replay ${PAPER_ARGS:-}
}

learner_flags() {  # a learner's label -> its flags (the clap's CPU grids used the same)
  case $1 in
    ddpg) echo "--algo ddpg" ;;
    td3) echo "--algo td3" ;;
    nstep3) echo "--ddpg.n-step 3" ;;
    twin) echo "--ddpg.twin-critics" ;;
    layernorm) echo "--ddpg.layer-norm" ;;
    smoothing) echo "--ddpg.target-policy-noise 0.2 --ddpg.target-noise-clip 0.5" ;;
    delay) echo "--ddpg.actor-update-interval 2" ;;
    c51) echo "--ddpg.num-atoms 51" ;;
    *) echo "unknown learner $1" >&2; return 1 ;;
  esac
}

learners() {
  # The paper's DDPG against --algo td3 (and, with LEARNERS, each option alone): 5 seeds
  # each (without imitation, as the authors' configs, unless LEARNER_VARIANT), the grids in
  # equal shares of what is left, then compare.
  task=${LEARNER_TASK:-handshake}
  set -- ${LEARNERS:-ddpg layernorm td3}
  n=$#
  pairs=""
  for learner in "$@"; do
    flags=$(learner_flags "$learner") || return 1
    left=$((BUDGET_S - SECONDS))
    minutes=$(python3 -c "print(max(0.5, ($left / $n - 120) / 60))")
    n=$((n - 1))
    echo "== learners $learner on $task: ${left} s left, --max-minutes ${minutes}" | tee -a "$OUT/session.log"
    rm -rf "/tmp/learners-$learner"
    timeout -s INT "$((left - 10))" python3 -m mjx_hands.experiments run --task "$task" \
      --preset gpu --variants "${LEARNER_VARIANT:-no_imitation}" --seeds "${LEARNER_SEEDS:-5}" \
      --num-envs "${GRID_ENVS:-1024}" --eval-envs 256 \
      --ddpg.batch-size 1024 --ddpg.replay-capacity 250000 --ddpg.min-replay-size 10240 \
      --no-save-replay --epochs 1000 --max-minutes "$minutes" --run-dir "/tmp/learners-$learner" \
      $flags ${GRID_ARGS:-} $TINY 2>&1 | tee "$OUT/learners-$learner.log"
    (cd /tmp && find "learners-$learner" -name checkpoints -prune -o -name best -prune -o -type f \
      -print | tar -cf - -T -) | tar -xf - -C "$OUT"
    pairs="$pairs $learner=$OUT/learners-$learner"
  done
  python3 -m mjx_hands.experiments compare $pairs --variant "${LEARNER_VARIANT:-no_imitation}" \
    --out "$OUT/learners" 2>&1 | tee "$OUT/learners.log"
}

target() {
  # The issue's GPU target: the handshake to 90 % success at the end, minutes from launch
  # (compiles included), ddpg-ln then the paper's DDPG, each given half of what is left.
  left=$((BUDGET_S - SECONDS))
  minutes=${TIME_MINUTES:-$(python3 -c "print(max(0.5, ($left / 2 - 60) / 60))")}
  echo "== time to 90 %: ${left} s left, at most ${minutes} min per learner" | tee -a "$OUT/session.log"
  # shellcheck disable=SC2086  # TINY holds several flags
  timeout -s INT "$((left - 10))" python3 -m benchmarks.time_to_target --tasks ${TIME_TASKS:-handshake} \
    --algos ddpg-ln ddpg --minutes "$minutes" --mocap-source synthetic \
    --out "$OUT/results_time_to_target_gpu.json" -- $TINY 2>&1 | tee "$OUT/time.log"
}

# What each stage leaves in $OUT when it worked (a dry run fails without it).
declare -A RESULT=(
  [throughput]=results_gpu.json [train]=metrics.csv [grid]=fig4/summary.json
  [learners]=learners [target]=results_time_to_target_gpu.json [paper]=paper-fig4/summary.json
  [physics]=physics/trained
)
for stage in $STAGES; do
  case $stage in
    throughput|train|grid|learners|target|paper|physics) "$stage" ;;
    *) echo "unknown stage $stage; expected throughput, train, grid, learners, target, paper or physics" >&2; exit 2 ;;
  esac
done
echo "== done after ${SECONDS} s" | tee -a "$OUT/session.log"
missing=""
for stage in $STAGES; do
  [ -e "$OUT/${RESULT[$stage]}" ] || missing="$missing $stage ($OUT/${RESULT[$stage]})"
done
if [ -n "$missing" ]; then
  echo "== stages without their results:$missing" | tee -a "$OUT/session.log"
  [ "$DRY_RUN" = 1 ] && exit 1  # a real session keeps whatever the budget allowed
fi

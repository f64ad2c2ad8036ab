"""The training run behind ``train.py``: config, presets, loop, logs, checkpoints.

The Python loop only calls the compiled epoch, evaluates, logs and checkpoints
(:mod:`mjx_hands.agents.ddpg`). A run directory holds ``config.json``,
``metrics.csv`` (one row per epoch; evaluation columns filled every ``eval_every``
epochs), TensorBoard event files, ``checkpoints/`` (Orbax; the latest few, to
resume from), ``best/`` (the policy of the best evaluation so far) and ``success.png``.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
import resource
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any, Literal

import jax
import numpy as np

from mjx_hands import checkpoint, tasks
from mjx_hands.agents.ddpg import DDPG, DDPGConfig, TrainerState

Task = Literal[tasks.TASKS]  # the registry's names, as choices of --task


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Train a hand-interaction policy with DDPG (or Brax's SAC/PPO for comparison)."""

    task: Task = "handshake"
    """Interaction to learn."""
    reward: Literal["full", "baseline1", "baseline2"] = "full"
    """Reward: the paper's full reward, baseline1 (palm position only), baseline2
    (no contact term)."""
    imitation: bool = True
    """Imitation terms r_pI, r_αI (time-indexed imitation of the demonstration)."""
    mocap: str | None = None
    """Folder of demonstrations; default: the authors' recordings in
    ../shared/mocap/drl_handshake when present, else the project's mocap_data/."""
    mocap_source: Literal["auto", "optitrack", "synthetic"] = "auto"
    """Which demonstrations to read."""
    target_rotation_noise: float = 0.0
    """Std (radians) of a random per-episode rotation of the target hand."""
    physics: Literal["auto", "mjx", "native"] = "auto"
    """Physics: MJX (accelerators), native C MuJoCo on every CPU core (>10x MJX's speed
    there) or auto (native on CPUs, MJX elsewhere)."""
    algo: Literal["ddpg", "sac", "ppo"] = "ddpg"
    """Learner: DDPG (the paper's) or Brax's SAC / PPO on the same environment."""
    preset: Literal["auto", "cpu", "gpu"] = "auto"
    """Size of the run; auto picks by the device JAX finds."""
    num_envs: int = 64
    """Parallel environments (summed over devices)."""
    epochs: int = 100
    """Training epochs (see --ddpg.iterations-per-epoch etc. for an epoch's size)."""
    max_minutes: float | None = None
    """Stop (with a checkpoint) once training has run this long."""
    eval_every: int = 5
    """Evaluate (and checkpoint) every this many epochs."""
    eval_envs: int = 64
    """Episodes per evaluation (summed over devices), deterministic policy."""
    seed: int = 0
    """Seed of networks, exploration and episode randomisation."""
    run_dir: str | None = None
    """Output folder; default runs/<task>-<algo>-<time>."""
    resume: bool = False
    """Continue the run in --run-dir from its latest checkpoint."""
    save_replay: bool = True
    """Include the replay buffer in checkpoints (resume then equals an uninterrupted run)."""
    ddpg: DDPGConfig = DDPGConfig()
    """DDPG hyperparameters."""

    def __post_init__(self):
        problems = []
        for name in ("num_envs", "epochs", "eval_every", "eval_envs"):
            if getattr(self, name) <= 0:
                problems.append(
                    f"--{name.replace('_', '-')} must be positive, got {getattr(self, name)}"
                )
        if self.max_minutes is not None and self.max_minutes <= 0:
            problems.append(f"--max-minutes must be positive, got {self.max_minutes}")
        if self.target_rotation_noise < 0:
            problems.append("--target-rotation-noise must be >= 0")
        if problems:
            raise ValueError("; ".join(problems))


def preset(kind: str, **overrides: Any) -> TrainConfig:
    """Default config of a preset: 'cpu' (2 cores, under an hour) or 'gpu' (thousands of envs)."""
    if kind == "auto":
        kind = "gpu" if jax.default_backend() in ("gpu", "cuda", "rocm", "tpu") else "cpu"
    if kind == "cpu":
        base = TrainConfig(
            preset="cpu",
            num_envs=64,
            epochs=100,  # 640 k env steps, ~45 min on 2 quiet cores (~275 env steps/s with SGD)
            eval_envs=64,
            ddpg=DDPGConfig(
                replay_capacity=200_000,
                unroll_length=10,
                updates_per_iteration=64,
                iterations_per_epoch=10,
            ),
        )
    elif kind == "gpu":
        base = TrainConfig(
            preset="gpu",
            num_envs=4096,
            epochs=200,
            eval_envs=1024,
            save_replay=False,
            ddpg=DDPGConfig(
                batch_size=4096,
                replay_capacity=2_000_000,
                min_replay_size=40_960,
                unroll_length=5,
                # Replay ratio 25.6 as in the CPU preset (128 x 4,096 / 20,480): the H100
                # handshake run reached 86 % in 6.35 M steps with it; updates are cheap on a GPU.
                updates_per_iteration=128,
                iterations_per_epoch=10,
            ),
        )
    else:
        raise ValueError(f"unknown preset {kind!r}; expected auto, cpu or gpu")
    return dataclasses.replace(base, **overrides)


# ---------------------------------------------------------------- build
def make_envs(config: TrainConfig, num_devices: int):
    """(train env, eval env, single env) with per-device batch sizes."""
    from mjx_hands import env as env_lib

    for name in ("num_envs", "eval_envs"):
        if getattr(config, name) % num_devices:
            raise ValueError(
                f"--{name.replace('_', '-')}={getattr(config, name)} is not divisible by "
                f"the {num_devices} devices"
            )
    single = env_lib.HandInteractionEnv(
        env_lib.EnvConfig(
            task=config.task,
            reward=config.reward,
            imitation=config.imitation,
            mocap_source=config.mocap_source,
            mocap_path=config.mocap,
            target_rotation_noise=config.target_rotation_noise,
            physics=config.physics,
        )
    )
    train_env = env_lib.BatchedEnv(single, config.num_envs // num_devices)
    eval_env = env_lib.BatchedEnv(single, config.eval_envs // num_devices)
    return train_env, eval_env, single


def make_learner(config: TrainConfig, devices=None, env_factory=None) -> tuple[DDPG, Any]:
    """The DDPG learner of ``config`` and its single (unbatched) environment.

    ``env_factory(config, num_devices) -> (train_env, eval_env, single_env)`` replaces
    the hand environment (tests train the point-reach task through the same loop).
    """
    num_devices = len(devices or jax.local_devices())  # this host's share of the batch
    train_env, eval_env, single = (env_factory or make_envs)(config, num_devices)
    algo = DDPG(
        train_env,
        config.ddpg,
        episode_length=single.episode_length,
        eval_env=eval_env,
        devices=devices,
    )
    return algo, single


# ------------------------------------------------------------- logging
class MetricsLog:
    """metrics.csv + TensorBoard events in the run directory; appends on resume."""

    def __init__(self, run_dir: Path):
        self.path = run_dir / "metrics.csv"
        self.rows: list[dict[str, float]] = []
        if self.path.exists():
            with self.path.open() as f:
                self.rows = [
                    {k: float(v) for k, v in r.items() if v not in ("", None) and k is not None}
                    for r in csv.DictReader(f)
                ]
        try:
            from tensorboardX import SummaryWriter

            self.tb = SummaryWriter(str(run_dir / "tensorboard"))
        except ImportError:  # pragma: no cover - tensorboardX is a dependency
            self.tb = None

    def append(self, row: dict[str, float]) -> None:
        self.rows.append(row)
        keys: list[str] = []
        for r in self.rows:
            keys += [k for k in r if k not in keys]
        # Rewritten whole (columns may grow) into a temporary file, then renamed, so
        # an interruption never leaves a truncated history.
        tmp = self.path.with_suffix(".csv.tmp")
        with tmp.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=keys)
            writer.writeheader()
            writer.writerows(self.rows)
        os.replace(tmp, self.path)
        if self.tb is not None:
            step = int(row["train/env_steps"])
            for k, v in row.items():
                # NaN means "nothing to report" (no episode ended): a gap, not a point.
                if k not in ("epoch", "train/env_steps") and math.isfinite(v):
                    self.tb.add_scalar(k, v, step)
            self.tb.flush()

    def close(self) -> None:
        if self.tb is not None:
            self.tb.close()


def plot_success(rows: list[dict[str, float]], path: Path, title: str) -> None:
    """Evaluation success rates and the training return against env steps, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax_return) = plt.subplots(1, 2, figsize=(10, 4))
    evals = [r for r in rows if "eval/success" in r]
    if evals:
        steps = [r["train/env_steps"] for r in evals]
        ax.plot(steps, [r["eval/success"] for r in evals], "o-", label="contact reached")
        if all("eval/success_final" in r for r in evals):
            finals = [r["eval/success_final"] for r in evals]
            ax.plot(steps, finals, "s--", label="contact at the end")
        ax.legend(loc="best")
    ax.set_xlabel("environment steps")
    ax.set_ylabel("evaluation success rate")
    ax.set_ylim(-0.02, 1.02)
    ax.grid(alpha=0.3)
    train = [r for r in rows if "train/episode_return" in r and r.get("train/episodes", 1) > 0]
    if train:
        ax_return.plot(
            [r["train/env_steps"] for r in train], [r["train/episode_return"] for r in train]
        )
    ax_return.set_xlabel("environment steps")
    for a in (ax, ax_return):  # 1e5-scale step counts: plain tick labels run together
        a.ticklabel_format(axis="x", style="sci", scilimits=(0, 0))
    ax_return.set_ylabel("training episode return (exploring)")
    ax_return.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# ----------------------------------------------------------------- run
def checkpoint_tree(state: TrainerState, save_replay: bool) -> dict[str, Any]:
    tree = {
        "learner": jax.tree.map(_first_device, state.learner),
        "env_state": state.env_state,
        "stats": state.stats,
        "rng": state.rng,
        "env_steps": state.env_steps,
    }
    if save_replay:
        tree["buffer"] = state.buffer
    return tree


def policy_tree(state: TrainerState) -> dict[str, Any]:
    """What a policy needs (the learner: networks, targets, normaliser); no env or buffer."""
    return {"learner": jax.tree.map(_first_device, state.learner)}


def _eval_rank(row: dict[str, float]) -> tuple[float, float, float]:
    """Order of evaluations for the best policy: success, then success at the end, then return."""
    return (row["eval/success"], row["eval/success_final"], row["eval/episode_return"])


def _first_device(x):
    """Device 0's slice of a replicated leaf; also for abstract (eval_shape) leaves."""
    if isinstance(x, jax.ShapeDtypeStruct):
        return jax.ShapeDtypeStruct(x.shape[1:], x.dtype)
    return x[0]


def _from_checkpoint_tree(tree: dict[str, Any], fresh: TrainerState, algo: DDPG) -> TrainerState:
    n = algo.num_devices
    learner = jax.tree.map(lambda x: np.broadcast_to(x, (n,) + x.shape), tree["learner"])
    state = fresh.replace(
        learner=learner,
        env_state=tree["env_state"],
        stats=tree["stats"],
        rng=tree["rng"],
        env_steps=tree["env_steps"],
        buffer=tree.get("buffer", fresh.buffer),
    )
    # Laid out as the epoch's outputs: any other sharding retraces (and recompiles) the epoch.
    return algo.to_devices(state)


def config_to_json(config: TrainConfig) -> dict[str, Any]:
    return dataclasses.asdict(config)


def config_from_json(data: dict[str, Any]) -> TrainConfig:
    data = dict(data)
    ddpg = dict(data.pop("ddpg"))
    for key in ("hidden_sizes", "target_clip"):
        if ddpg.get(key) is not None:
            ddpg[key] = tuple(ddpg[key])
    return TrainConfig(**data, ddpg=DDPGConfig(**ddpg))


BEST_DIR = "best"  # run_dir/best: the learner of the best evaluation, for evaluate --best

# Settings a resumed run must share with its checkpoint: they fix the task, the physics,
# the networks' and buffers' shapes. Everything else (learning rates, budget) may change.
RESUME_FIXED = (
    "task",
    "reward",
    "imitation",
    "mocap_source",
    "mocap",
    "physics",
    "num_envs",
    "algo",
    "ddpg.hidden_sizes",
    "ddpg.layer_norm",
    "ddpg.batch_norm",
    "ddpg.replay_capacity",
)


def _check_resumable(saved: dict[str, Any], config: TrainConfig, run_dir: Path) -> None:
    current = json.loads(json.dumps(config_to_json(config)))  # tuples as JSON lists
    # Through the dataclass: settings added since the run started take their defaults.
    saved = json.loads(json.dumps(config_to_json(config_from_json(saved))))

    def get(tree, dotted):
        for part in dotted.split("."):
            tree = tree.get(part) if isinstance(tree, dict) else None
        return tree

    for key in RESUME_FIXED:
        if get(saved, key) != get(current, key):
            raise checkpoint.CheckpointError(
                f"--resume: {run_dir} was trained with {key}={get(saved, key)!r}, "
                f"this command asks for {get(current, key)!r}"
            )


def _interrupt_on_sigterm():
    """Make SIGTERM (``kill``, batch schedulers, and the only stop signal a job started in
    the background with ``&`` receives: its SIGINT is ignored) stop training like Ctrl-C.
    Returns the previous handler, or None off the main thread (where none can be set)."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def interrupt(signum, frame):
        raise KeyboardInterrupt(f"signal {signum}")

    return signal.signal(signal.SIGTERM, interrupt)


class TrainingDiverged(RuntimeError):
    """Losses or parameters became NaN/inf; the last good checkpoint is kept."""


def run_directory(config: TrainConfig) -> Path:
    """``--run-dir``, or runs/<task>-<algo>-<time> when none is given."""
    return Path(
        config.run_dir or f"runs/{config.task}-{config.algo}-{time.strftime('%Y%m%d-%H%M%S')}"
    )


def run(config: TrainConfig, out=sys.stdout, env_factory=None) -> dict[str, Any]:
    """Train DDPG according to ``config``; returns a summary (final metrics, paths).

    ``env_factory``: see :func:`make_learner` (default: the hand environment). Brax's
    SAC and PPO run through :func:`mjx_hands.brax_agents.run` (train.py picks).
    """
    if config.algo != "ddpg":
        raise ValueError(
            f"training.run trains DDPG; --algo {config.algo} runs through "
            "mjx_hands.brax_agents.run (train.py dispatches by --algo)"
        )
    launched = time.perf_counter()  # wall clock from here includes the compiles
    run_dir = run_directory(config)
    ckpt_dir = run_dir / "checkpoints"
    best_dir = run_dir / BEST_DIR
    config_path = run_dir / "config.json"
    if config.resume:
        if not config_path.is_file():
            raise FileNotFoundError(
                f"--resume: no run to continue in {run_dir} (config.json missing)"
            )
        _check_resumable(json.loads(config_path.read_text()), config, run_dir)
    elif config_path.exists() and checkpoint.latest_step(ckpt_dir) is not None:
        raise FileExistsError(
            f"{run_dir} already holds a run; pass --resume to continue it or choose another --run-dir"
        )
    run_dir.mkdir(parents=True, exist_ok=True)
    print(f"building the {config.task} environment and learner ...", file=out, flush=True)
    algo, single = make_learner(config, env_factory=env_factory)
    demos = getattr(single, "demos", None)
    source = f"{len(demos)} demonstrations ({demos[0].source})" if demos else type(single).__name__
    print(
        f"{config.task}: {source}, {getattr(single, 'backend', '?')} physics, "
        f"{config.num_envs} envs on {algo.num_devices} {jax.default_backend()} device(s), "
        f"episode {single.episode_length} steps, run dir {run_dir} "
        f"({time.perf_counter() - launched:.0f} s)",
        file=out,
        flush=True,
    )
    key = jax.random.PRNGKey(config.seed)
    state = algo.init(key)
    start_epoch = 0
    if config.resume and checkpoint.latest_step(ckpt_dir) is not None:
        # The checkpoint's own setting says whether it holds the replay buffer.
        saved_replay = checkpoint.read_metadata(ckpt_dir)["config"]["save_replay"]
        tree, meta = checkpoint.restore(ckpt_dir, checkpoint_tree(state, saved_replay))
        state = _from_checkpoint_tree(tree, state, algo)
        start_epoch = int(meta["epoch"])
        print(f"resumed from epoch {start_epoch}", file=out, flush=True)
    # Written once the run is known to start (a refused resume leaves the old one).
    config_path.write_text(json.dumps(config_to_json(config), indent=2))

    log = MetricsLog(run_dir)
    log.rows = [r for r in log.rows if r.get("epoch", 0) <= start_epoch]
    # A resumed run's wall clock continues from where its kept rows end.
    launched -= log.rows[-1].get("time/wall_seconds", 0.0) if log.rows else 0.0
    steps_per_epoch = config.num_envs * config.ddpg.unroll_length * config.ddpg.iterations_per_epoch
    started = time.perf_counter()
    last_saved = start_epoch
    stop_reason = "epochs"
    kept_evals = [r for r in log.rows if "eval/success" in r]
    best = max(kept_evals, key=_eval_rank, default=None)

    def save(epoch: int) -> None:
        nonlocal last_saved
        meta = {"epoch": epoch, "config": config_to_json(config), "num_devices": algo.num_devices}
        checkpoint.save(ckpt_dir, epoch, checkpoint_tree(state, config.save_replay), meta)
        last_saved = epoch

    def save_if_best(epoch: int, row: dict[str, float]) -> None:
        # DDPG's evaluations swing by tens of points (hand clap: 0.91 then 0.11 ten epochs
        # later); the latest checkpoint is for resuming, this one is the policy to use.
        nonlocal best
        if best is not None and _eval_rank(row) <= _eval_rank(best):
            return
        evals = {k: v for k, v in row.items() if k.startswith("eval/")}
        meta = {
            "epoch": epoch,
            "config": config_to_json(config),
            "num_devices": algo.num_devices,
            "contents": "policy",
            "eval": evals,
        }
        checkpoint.save(best_dir, epoch, policy_tree(state), meta, max_to_keep=1)
        best = row

    previous_sigterm = _interrupt_on_sigterm()
    if start_epoch < config.epochs:
        print(
            "compiling the training epoch (once; MJX on 2 CPU cores takes minutes, native "
            "physics seconds), then epoch 1 ...",
            file=out,
            flush=True,
        )
    try:
        for epoch in range(start_epoch + 1, config.epochs + 1):
            t0 = time.perf_counter()
            state, metrics = algo.run_epoch(state)
            seconds = time.perf_counter() - t0
            losses_finite = all(
                math.isfinite(v) for k, v in metrics.items() if k.startswith("sgd/")
            )
            if not losses_finite or metrics["train/params_finite"] < 1.0:
                bad = {
                    k: v
                    for k, v in metrics.items()
                    if k.startswith("sgd/") and not math.isfinite(v)
                }
                raise TrainingDiverged(
                    f"epoch {epoch}: training diverged (non-finite {sorted(bad) or 'parameters'}); "
                    f"the last good checkpoint (epoch {last_saved}) is in {ckpt_dir}; "
                    "lower the learning rates or enable --ddpg.layer-norm and --resume"
                )
            row = {
                "epoch": float(epoch),
                "time/epoch_seconds": seconds,
                "time/env_steps_per_second": steps_per_epoch / seconds,
                "time/wall_seconds": time.perf_counter() - launched,
            } | metrics
            peak = (jax.devices()[0].memory_stats() or {}).get("peak_bytes_in_use")
            if peak is not None:  # accelerators count; CPU does not
                row["memory/device_peak_gib"] = peak / 2**30
            # ru_maxrss is KiB on Linux.
            row["memory/host_peak_gib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
            evaluate = epoch % config.eval_every == 0 or epoch == config.epochs
            elapsed = time.perf_counter() - started
            out_of_time = config.max_minutes is not None and elapsed > 60 * config.max_minutes
            if evaluate or out_of_time:
                eval_key = jax.random.fold_in(jax.random.PRNGKey(config.seed + 1), epoch)
                row |= algo.evaluate(state, eval_key)
            log.append(row)
            remaining = (config.epochs - epoch) * elapsed / max(epoch - start_epoch, 1)
            if config.max_minutes is not None:  # whichever budget ends the run first
                remaining = min(remaining, max(60 * config.max_minutes - elapsed, 0.0))
            rate = row["time/env_steps_per_second"]
            line = f"epoch {epoch:4d}/{config.epochs}  {rate:8,.0f} steps/s  "
            if metrics["train/episodes"] > 0:
                line += (
                    f"return {metrics['train/episode_return']:8.2f}  "
                    f"train success {metrics['train/success']:.2f}"
                )
            else:
                line += "(no episode ended this epoch)"
            if "eval/success" in row:
                line += f"  eval success {row['eval/success']:.2f} (end {row['eval/success_final']:.2f})"
            line += f"  left ~{remaining / 60:.0f} min"
            print(line, file=out, flush=True)
            if evaluate or out_of_time:
                save(epoch)
                save_if_best(epoch, row)
            if out_of_time:
                stop_reason = "max_minutes"
                break
    except KeyboardInterrupt:
        stop_reason = "interrupted"
        print(f"\ninterrupted; the last checkpoint (epoch {last_saved}) is in {ckpt_dir}", file=out)
    finally:
        if previous_sigterm is not None:
            signal.signal(signal.SIGTERM, previous_sigterm)
        log.close()
        plot_success(
            log.rows, run_dir / "success.png", f"{config.task} ({config.algo}, {config.reward})"
        )
    evals = [r for r in log.rows if "eval/success" in r]
    return {
        "run_dir": str(run_dir),
        "stop_reason": stop_reason,
        "epochs": int(log.rows[-1]["epoch"]) if log.rows else start_epoch,
        "last_checkpoint": last_saved,
        "final_eval": {k: v for k, v in evals[-1].items() if k.startswith("eval/")}
        if evals
        else {},
        "best_eval_success": max((r["eval/success"] for r in evals), default=float("nan")),
        "best_checkpoint": int(best["epoch"]) if best is not None else None,
        "epoch_compilations": algo.trace_count,  # 1 unless something forced a retrace
    }

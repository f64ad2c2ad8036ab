"""The training run behind ``train.py``: config, presets, loop, logs, checkpoints.

The Python loop only calls the compiled epoch, evaluates, logs and checkpoints
(:mod:`mjx_hands.agents.ddpg`). A run directory holds ``config.json``,
``metrics.csv`` (one row per epoch; evaluation columns filled every ``eval_every``
epochs), TensorBoard event files, ``checkpoints/`` (Orbax; the latest few, to
resume from), ``best/`` (the policy of the best evaluation so far) and ``success.png``.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import functools
import json
import math
import os
import resource
import signal
import sys
import threading
import time
from collections.abc import Callable
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
    demos: Literal["authors", "all"] = "authors"
    """Of the recordings, the demonstrations the authors trained on, or all of them."""
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
    checkpoint_every: int = 1
    """Also checkpoint every this many epochs (a crash loses at most these epochs; the
    CPU preset: 5, as its replay buffer makes a checkpoint cost a third of an epoch)."""
    checkpoint_minutes: float | None = None
    """Also checkpoint once this many minutes have passed since the last checkpoint."""
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
    replay_ratio: float | None = None
    """Replayed transitions per collected one (updates x batch size / env steps), held as
    --num-envs changes: when set, it fixes --ddpg.updates-per-iteration (rounded to a
    multiple of --ddpg.actor-update-interval, at least one). Both presets replay 25.6."""

    def __post_init__(self):
        if (
            self.replay_ratio is not None
            and math.isfinite(self.replay_ratio)
            and self.replay_ratio > 0
        ):
            # Resolved here, so config.json records the updates the run makes.
            object.__setattr__(
                self, "ddpg", updates_for_ratio(self.ddpg, self.num_envs, self.replay_ratio)
            )
        problems = []
        for name in ("num_envs", "epochs", "eval_every", "eval_envs", "checkpoint_every"):
            if getattr(self, name) <= 0:
                problems.append(
                    f"--{name.replace('_', '-')} must be positive, got {getattr(self, name)}"
                )
        for name in ("max_minutes", "checkpoint_minutes"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                problems.append(
                    f"--{name.replace('_', '-')} must be a positive number, got {value}"
                )
        if self.replay_ratio is not None and not (
            math.isfinite(self.replay_ratio) and self.replay_ratio > 0
        ):
            problems.append(f"--replay-ratio must be a positive number, got {self.replay_ratio}")
        if not (math.isfinite(self.target_rotation_noise) and self.target_rotation_noise >= 0):
            problems.append(
                f"--target-rotation-noise must be a finite number >= 0, got "
                f"{self.target_rotation_noise}"
            )
        if self.mocap is not None and not Path(self.mocap).is_dir():
            problems.append(f"--mocap {self.mocap}: no such folder")
        if problems:
            raise ValueError("; ".join(problems))


def updates_for_ratio(ddpg: DDPGConfig, num_envs: int, ratio: float) -> DDPGConfig:
    """``ddpg`` with the updates per iteration that replay ``ratio`` sampled transitions per
    env step at ``num_envs`` envs: ratio x num_envs x unroll / batch, rounded to a multiple
    of the actor update interval (at least one interval)."""
    collected = num_envs * ddpg.unroll_length
    interval = ddpg.actor_update_interval
    updates = max(interval, interval * round(ratio * collected / ddpg.batch_size / interval))
    return dataclasses.replace(ddpg, updates_per_iteration=updates)


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
            # A 250 MB checkpoint (the replay buffer) takes ~2.4 s against a ~6.5 s epoch
            # (native physics): every 5th epoch costs 7 %, every epoch 37 % (RESULTS.md).
            checkpoint_every=5,
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
            demos=config.demos,
            target_rotation_noise=config.target_rotation_noise,
            physics=config.physics,
        )
    )
    train_env = env_lib.BatchedEnv(single, config.num_envs // num_devices)
    eval_env = env_lib.BatchedEnv(single, config.eval_envs // num_devices)
    return train_env, eval_env, single


def make_learner(
    config: TrainConfig, devices=None, env_factory=None, population: list | None = None
) -> tuple[DDPG, Any]:
    """The DDPG learner of ``config`` and its single (unbatched) environment.

    ``env_factory(config, num_devices) -> (train_env, eval_env, single_env)`` replaces
    the hand environment (tests train the point-reach task through the same loop).
    ``population``: the configs of every member (``config`` is the first), each with its
    reward variant as data; None trains ``config`` alone.
    """
    num_devices = len(devices or jax.local_devices())  # this host's share of the batch
    train_env, eval_env, single = (env_factory or make_envs)(config, num_devices)
    members = population or [config]
    algo = DDPG(
        train_env,
        config.ddpg,
        episode_length=single.episode_length,
        eval_env=eval_env,
        devices=devices,
        members=len(members),
        member_info=member_variants(single, members),
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
        if all("eval/success_final" in r for r in evals):
            finals = [r["eval/success_final"] for r in evals]
            ax.plot(steps, finals, "o-", lw=2, label="contact at the end (headline)")
        ax.plot(
            steps,
            [r["eval/success"] for r in evals],
            "s--",
            alpha=0.7,
            label="contact at some step",
        )
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
def eval_rank(row: dict[str, float]) -> tuple[float, float, float]:
    """Order of evaluations for the best policy: success at the end of the episode (the
    authors' metric), then success at some step, then the return."""
    return (row["eval/success_final"], row["eval/success"], row["eval/episode_return"])


def memory_use() -> dict[str, float]:
    """Host memory now and at its peak, and device memory where the device counts it
    (accelerators; CPU does not), GiB: logged every epoch so growth shows."""
    stats = jax.devices()[0].memory_stats() or {}
    use = {
        f"memory/device_{name}_gib": stats[key] / 2**30
        for name, key in (("peak", "peak_bytes_in_use"), ("in_use", "bytes_in_use"))
        if key in stats
    }
    # ru_maxrss is KiB on Linux; the resident set now from /proc (Linux only).
    use["memory/host_peak_gib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    with contextlib.suppress(OSError, IndexError, ValueError):
        pages = int(Path("/proc/self/statm").read_text().split()[1])
        use["memory/host_rss_gib"] = pages * os.sysconf("SC_PAGE_SIZE") / 2**30
    return use


def read_config_json(path: Path) -> dict[str, Any]:
    """A run's config.json as a dict; a damaged file is an error naming it."""
    try:
        data = json.loads(Path(path).read_text())
        if not isinstance(data, dict):
            raise TypeError(f"it holds a JSON {type(data).__name__}, not an object")
    except (OSError, ValueError, TypeError) as err:
        raise ValueError(f"{path} is unreadable ({err}); restore it or start a new run") from err
    return data


def config_to_json(config: TrainConfig) -> dict[str, Any]:
    return dataclasses.asdict(config)


def config_from_json(data: dict[str, Any]) -> TrainConfig:
    data = dict(data)
    data.setdefault("demos", "all")  # runs from before the setting used every demonstration
    ddpg = dict(data.pop("ddpg"))
    for key in ("hidden_sizes", "target_clip", "value_range"):
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
    "demos",
    "physics",
    "num_envs",
    "algo",
    "ddpg.hidden_sizes",
    "ddpg.layer_norm",
    "ddpg.batch_norm",
    "ddpg.twin_critics",
    "ddpg.num_atoms",
    "ddpg.replay_capacity",
)

MEMBER_FIELDS = ("seed", "reward", "imitation", "run_dir")
"""What members of one population may differ in; every other setting is shared (one
program): seeds, and reward variants as data."""


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


class Interrupts:
    """Ctrl-C and SIGTERM stop training with a KeyboardInterrupt, but never in the middle
    of saving: a population's members save one after another, and a stop between two of
    them would leave the run directories at different epochs. SIGTERM matters: ``kill``,
    batch schedulers, and the only stop signal a job started in the background with ``&``
    receives (its SIGINT is ignored). Off the main thread nothing is installed."""

    def __init__(self):
        self.pending: int | None = None
        self.saving = False
        self.previous: dict[int, Any] = {}

    def install(self) -> None:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                if signal.getsignal(sig) is not signal.SIG_IGN:
                    self.previous[sig] = signal.signal(sig, self._handle)

    def uninstall(self) -> None:
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)
        self.previous = {}

    def _handle(self, signum, frame):
        if self.saving:
            self.pending = signum
            return
        raise KeyboardInterrupt(f"signal {signum}")

    @contextlib.contextmanager
    def deferred(self):
        """Hold a stop until the block (e.g. the saves of one epoch) is done."""
        self.saving = True
        try:
            yield
        finally:
            self.saving = False
        if self.pending is not None:
            raise KeyboardInterrupt(f"signal {self.pending}")


class TrainingDiverged(RuntimeError):
    """Losses or parameters became NaN/inf; the last good checkpoint is kept."""


def run_directory(config: TrainConfig) -> Path:
    """``--run-dir``, or runs/<task>-<algo>-<time> when none is given."""
    return Path(
        config.run_dir or f"runs/{config.task}-{config.algo}-{time.strftime('%Y%m%d-%H%M%S')}"
    )


class RunDirectory:
    """One run's folder: config.json, metrics.csv + TensorBoard, checkpoints/, best/,
    success.png. A member of a population has one like any run (``evaluate`` opens it)."""

    def __init__(self, config: TrainConfig):
        self.config = config
        self.path = run_directory(config)
        self.checkpoints = self.path / "checkpoints"
        self.best_dir = self.path / BEST_DIR
        self.config_path = self.path / "config.json"
        self.last_saved = 0
        self.best: dict[str, float] | None = None
        self.log: MetricsLog | None = None

    def check(self) -> None:
        """Refuse a resume without a run and a fresh start over an existing run."""
        if self.config.resume:
            if not self.config_path.is_file():
                raise FileNotFoundError(
                    f"--resume: no run to continue in {self.path} (config.json missing)"
                )
            _check_resumable(read_config_json(self.config_path), self.config, self.path)
        elif self.config_path.exists() and checkpoint.steps(self.checkpoints):
            raise FileExistsError(
                f"{self.path} already holds a run; pass --resume to continue it or choose "
                "another --run-dir"
            )

    def latest_epoch(self) -> int | None:
        """The newest intact checkpoint's epoch when resuming (damaged ones: a warning)."""
        return checkpoint.latest_step(self.checkpoints) if self.config.resume else None

    def last_checkpoint(self) -> str:
        """Where training would continue from, for messages."""
        if self.last_saved == 0:
            return "no checkpoint was saved yet"
        return f"the last checkpoint (epoch {self.last_saved}) is in {self.checkpoints}"

    def restore(
        self, algo: DDPG, like: TrainerState, index: int, epoch: int, verified: bool = False
    ) -> dict[str, Any]:
        """Member ``index``'s checkpoint tree of ``epoch`` (``algo``'s layout, shaped like
        ``like``'s). ``verified``: :meth:`latest_epoch` returned ``epoch``, so its digest
        was checked (hashing reads every byte of the step: a replay buffer is GBs)."""
        num_devices = algo.num_devices
        meta = checkpoint.read_metadata(self.checkpoints, epoch, verified=verified)
        saved_devices = int(meta.get("num_devices", 1))
        if saved_devices != num_devices:
            raise checkpoint.CheckpointError(
                f"--resume: {self.path} was trained on {saved_devices} device(s), this process "
                f"has {num_devices}; resume with {saved_devices} (CPU: XLA_FLAGS="
                f"--xla_force_host_platform_device_count={saved_devices})"
            )
        # The checkpoint's own setting says whether it holds the replay buffer.
        saved_replay = meta["config"]["save_replay"]
        tree, _ = checkpoint.restore(
            self.checkpoints,
            algo.checkpoint_tree(like, saved_replay, index),
            epoch,
            verified=True,  # checked by read_metadata above or by latest_epoch
        )
        return tree

    def open(self, start_epoch: int) -> None:
        """Write config.json (the run is known to start) and open the metrics log, keeping
        the rows up to ``start_epoch``."""
        self.path.mkdir(parents=True, exist_ok=True)
        self.config_path.write_text(json.dumps(config_to_json(self.config), indent=2))
        self.log = MetricsLog(self.path)
        self.log.rows = [r for r in self.log.rows if r.get("epoch", 0) <= start_epoch]
        self.best = max(
            (r for r in self.log.rows if "eval/success" in r), key=eval_rank, default=None
        )
        if self.best is not None and not self._best_saved(int(self.best["epoch"])):
            self.best = None  # killed while saving it: the next evaluation saves a best
        self.last_saved = start_epoch

    def _best_saved(self, epoch: int) -> bool:
        """Whether best/ holds an intact policy of ``epoch``; a damaged one is set aside."""
        if epoch not in checkpoint.steps(self.best_dir):
            return False
        if checkpoint.damage(self.best_dir, epoch) is None:
            return True
        checkpoint.discard_after(self.best_dir, epoch - 1)
        return False

    def wall_offset(self) -> float:
        """Seconds a resumed run had already run (its kept rows' wall clock)."""
        return self.log.rows[-1].get("time/wall_seconds", 0.0) if self.log.rows else 0.0

    def metadata(self, epoch: int, num_devices: int) -> dict[str, Any]:
        return {"epoch": epoch, "config": config_to_json(self.config), "num_devices": num_devices}

    def save(self, tree: dict[str, Any], epoch: int, num_devices: int) -> None:
        """Write ``tree`` (the learner's checkpoint layout) as the checkpoint of ``epoch``."""
        checkpoint.save(self.checkpoints, epoch, tree, self.metadata(epoch, num_devices))
        self.last_saved = epoch

    def save_if_best(
        self,
        policy: Callable[[], dict[str, Any]],
        epoch: int,
        row: dict[str, float],
        num_devices: int,
    ) -> None:
        """Keep ``policy()`` (the learner's policy tree) in best/ when ``row`` evaluates
        better than every earlier evaluation."""
        # DDPG's evaluations swing by tens of points (hand clap: 0.91 then 0.11 ten epochs
        # later); the latest checkpoint is for resuming, this one is the policy to use.
        if self.best is not None and eval_rank(row) <= eval_rank(self.best):
            return
        evals = {k: v for k, v in row.items() if k.startswith("eval/")}
        meta = self.metadata(epoch, num_devices) | {"contents": "policy", "eval": evals}
        checkpoint.save(self.best_dir, epoch, policy(), meta, max_to_keep=1)
        self.best = row

    def close(self) -> None:
        if self.log is None:
            return
        self.log.close()
        title = f"{self.config.task} ({self.config.algo}, {self.config.reward}"
        title += ")" if self.config.imitation else ", no imitation)"
        plot_success(self.log.rows, self.path / "success.png", title)

    def summary(self, stop_reason: str, start_epoch: int) -> dict[str, Any]:
        rows = self.log.rows if self.log is not None else []
        evals = [r for r in rows if "eval/success" in r]
        return {
            "run_dir": str(self.path),
            "stop_reason": stop_reason,
            "epochs": int(rows[-1]["epoch"]) if rows else start_epoch,
            "last_checkpoint": self.last_saved,
            "final_eval": {k: v for k, v in evals[-1].items() if k.startswith("eval/")}
            if evals
            else {},
            "best_eval_success_final": max(
                (r["eval/success_final"] for r in evals), default=float("nan")
            ),
            "best_eval_success": max((r["eval/success"] for r in evals), default=float("nan")),
            "best_checkpoint": int(self.best["epoch"]) if self.best is not None else None,
        }


def _check_population(configs: list[TrainConfig]) -> None:
    if not configs:
        raise ValueError("a population needs at least one run config")
    shared = lambda c: {k: v for k, v in config_to_json(c).items() if k not in MEMBER_FIELDS}
    for config in configs[1:]:
        a, b = shared(configs[0]), shared(config)
        if a != b:
            diff = sorted(k for k in a if a[k] != b[k])
            raise ValueError(
                f"members of a population may differ only in {', '.join(MEMBER_FIELDS)}; "
                f"{config.run_dir} differs from {configs[0].run_dir} in {', '.join(diff)}"
            )
    dirs = [str(run_directory(c)) for c in configs]
    if len(set(dirs)) != len(dirs):
        raise ValueError(f"members need distinct run directories, got {dirs}")
    if any(c.algo != "ddpg" for c in configs):
        raise ValueError(
            f"training.run trains DDPG; --algo {configs[0].algo} runs through "
            "mjx_hands.brax_agents.run (train.py dispatches by --algo)"
        )


def member_variants(single, configs: list[TrainConfig]) -> dict[str, Any] | None:
    """``member_info`` giving each member its reward variant as data, or None when all
    members use the environment's own variant (``configs[0]``'s)."""
    if all((c.reward, c.imitation) == (configs[0].reward, configs[0].imitation) for c in configs):
        return None
    from mjx_hands import env as env_lib

    weights = [
        single.variant_for(
            env_lib.reward_weights(env_lib.EnvConfig(reward=c.reward, imitation=c.imitation))
        )
        for c in configs
    ]
    return {"reward_weights": jax.tree.map(lambda *xs: np.stack(xs), *weights)}


def _newly_diverged(
    epoch: int, metrics: list[dict[str, float]], runs: list[RunDirectory], diverged: set[int]
) -> list[int]:
    """Members whose losses or parameters turned non-finite this epoch. A run alone stops
    (TrainingDiverged); in a population the others train on (members share no numbers),
    and the diverged one keeps its last good checkpoint and logs no more."""
    new = []
    for index, (metrics_m, run_m) in enumerate(zip(metrics, runs)):
        bad = sorted(
            k for k, v in metrics_m.items() if k.startswith("sgd/") and not math.isfinite(v)
        )
        if index in diverged or not (bad or metrics_m["train/params_finite"] < 1.0):
            continue
        message = (
            f"epoch {epoch}: training diverged (non-finite {bad or 'parameters'}) in "
            f"{run_m.path}; {run_m.last_checkpoint().replace('the last', 'the last good')}"
        )
        if len(runs) == 1:
            raise TrainingDiverged(
                message + "; lower the learning rates or enable --ddpg.layer-norm and --resume"
            )
        new.append(index)
        print(f"{message}; the other members train on", file=sys.stderr, flush=True)
    return new


def _progress_line(
    epoch: int, epochs: int, rate: float, rows: list[dict], labels: list[str]
) -> str:
    """One line per epoch: the run's figures, or each variant's mean over its members."""
    line = f"epoch {epoch:4d}/{epochs}  {rate:8,.0f} steps/s  "
    if len(rows) == 1:
        row = rows[0]
        if row["train/episodes"] > 0:
            line += f"return {row['train/episode_return']:8.2f}  train success {row['train/success']:.2f}"
        else:
            line += "(no episode ended this epoch)"
        if "eval/success" in row:
            line += (
                f"  eval success at the end {row['eval/success_final']:.2f} "
                f"(some step {row['eval/success']:.2f})"
            )
        return line
    key = "eval/success_final" if "eval/success_final" in rows[0] else "train/success"
    groups: dict[str, list[float]] = {}
    for label, row in zip(labels, rows):
        groups.setdefault(label, []).append(row[key])
    what = "eval success at the end" if key.startswith("eval") else "train success"
    shown = "  ".join(f"{g} {np.nanmean(v):.2f}" for g, v in groups.items())
    return line + f"{what}: {shown}"


def run(config: TrainConfig, out=sys.stdout, env_factory=None) -> dict[str, Any]:
    """Train DDPG according to ``config``; returns a summary (final metrics, paths).

    ``env_factory``: see :func:`make_learner` (default: the hand environment). Brax's
    SAC and PPO run through :func:`mjx_hands.brax_agents.run` (train.py picks).
    """
    return run_population([config], out, env_factory)[0]


def run_population(
    configs: list[TrainConfig],
    out=sys.stdout,
    env_factory=None,
    labels: list[str] | None = None,
) -> list[dict[str, Any]]:
    """Train the runs ``configs`` together as one population (one compiled epoch).

    The configs may differ only in ``MEMBER_FIELDS`` (seed, reward variant, imitation,
    run directory); each member writes an ordinary run directory, and member ``i``
    trains as ``run(configs[i])`` alone would. ``labels`` group members in the progress
    line (e.g. by variant). Returns one summary per member.
    """
    _check_population(configs)
    config = configs[0]
    launched = time.perf_counter()  # wall clock from here includes the compiles
    runs = [RunDirectory(c) for c in configs]
    for r in runs:
        r.check()
    labels = labels or [str(r.path) for r in runs]
    print(f"building the {config.task} environment and learner ...", file=out, flush=True)
    algo, single = make_learner(config, env_factory=env_factory, population=configs)
    where = (
        runs[0].path
        if len(runs) == 1
        else f"{len(runs)} runs in {os.path.commonpath([str(r.path) for r in runs])}"
    )
    print(
        f"{config.task}: {single.describe()}, "
        f"{config.num_envs} envs{' per run' if len(runs) > 1 else ''} on {algo.num_devices} "
        f"{jax.default_backend()} device(s), episode {single.episode_length} steps, "
        f"run dir {where} ({time.perf_counter() - launched:.0f} s)",
        file=out,
        flush=True,
    )
    state = algo.init(np.stack([np.asarray(jax.random.PRNGKey(c.seed)) for c in configs]))
    saved = [r.latest_epoch() for r in runs]
    start_epoch = 0
    if any(s is not None for s in saved):
        if any(s is None for s in saved):
            missing = [str(r.path) for r, s in zip(runs, saved) if s is None]
            raise checkpoint.CheckpointError(f"--resume: no checkpoint in {', '.join(missing)}")
        start_epoch = min(saved)  # members save together; a crash mid-save leaves some ahead
        for r in runs:  # ... whose newer checkpoints the resumed run will write again
            checkpoint.discard_after(r.checkpoints, start_epoch)
            checkpoint.discard_after(r.best_dir, start_epoch)
        trees = [
            r.restore(algo, state, i, start_epoch, verified=s == start_epoch)
            for i, (r, s) in enumerate(zip(runs, saved, strict=True))
        ]
        state = algo.from_checkpoint_trees(trees, state)
        print(f"resumed from epoch {start_epoch}", file=out, flush=True)
    for r in runs:
        r.open(start_epoch)
    # A resumed run's wall clock continues from where its kept rows end.
    launched -= runs[0].wall_offset()
    steps_per_epoch = config.num_envs * config.ddpg.unroll_length * config.ddpg.iterations_per_epoch
    started = time.perf_counter()
    stop_reason = "epochs"
    last_save_time = started
    diverged: set[int] = set()
    interrupts = Interrupts()
    interrupts.install()
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
            diverged.update(_newly_diverged(epoch, metrics, runs, diverged))
            if len(diverged) == len(runs):
                raise TrainingDiverged(f"epoch {epoch}: every member of the population diverged")
            common = {
                "epoch": float(epoch),
                "time/epoch_seconds": seconds,
                "time/env_steps_per_second": steps_per_epoch / seconds,  # this run's
                "time/wall_seconds": time.perf_counter() - launched,
            }
            if len(runs) > 1:  # what the machine did: every member's steps
                common["time/population_env_steps_per_second"] = (
                    len(runs) * steps_per_epoch / seconds
                )
            common |= memory_use()
            rows = [common | m for m in metrics]
            evaluate = epoch % config.eval_every == 0 or epoch == config.epochs
            elapsed = time.perf_counter() - started
            out_of_time = config.max_minutes is not None and elapsed > 60 * config.max_minutes
            if evaluate or out_of_time:
                keys = np.stack(
                    [
                        np.asarray(jax.random.fold_in(jax.random.PRNGKey(c.seed + 1), epoch))
                        for c in configs
                    ]
                )
                rows = [row | e for row, e in zip(rows, algo.evaluate(state, keys))]
            for i, (r, row) in enumerate(zip(runs, rows)):
                if i not in diverged:
                    r.log.append(row)
            remaining = (config.epochs - epoch) * elapsed / max(epoch - start_epoch, 1)
            if config.max_minutes is not None:  # whichever budget ends the run first
                remaining = min(remaining, max(60 * config.max_minutes - elapsed, 0.0))
            rate = len(runs) * common["time/env_steps_per_second"]
            line = _progress_line(epoch, config.epochs, rate, rows, labels)
            print(f"{line}  left ~{remaining / 60:.0f} min", file=out, flush=True)
            since_save = time.perf_counter() - last_save_time
            if (
                evaluate
                or out_of_time
                or epoch % config.checkpoint_every == 0
                or (
                    config.checkpoint_minutes is not None
                    and since_save > 60 * config.checkpoint_minutes
                )
            ):
                with interrupts.deferred():
                    for i, (r, row) in enumerate(zip(runs, rows)):
                        if i in diverged:
                            continue
                        tree = algo.checkpoint_tree(state, r.config.save_replay, i)
                        r.save(tree, epoch, algo.num_devices)
                        if "eval/success" in row:
                            policy = functools.partial(algo.policy_tree, state, i)
                            r.save_if_best(policy, epoch, row, algo.num_devices)
                last_save_time = time.perf_counter()
            if out_of_time:
                stop_reason = "max_minutes"
                break
    except KeyboardInterrupt:
        stop_reason = "interrupted"
        if len(runs) == 1:
            where = runs[0].last_checkpoint()
        else:
            where = (
                f"the last checkpoint (epoch {runs[0].last_saved}) is in each run's checkpoints/"
            )
        print(f"\ninterrupted; {where}", file=out)
    finally:
        interrupts.uninstall()
        for r in runs:
            r.close()
    return [
        r.summary(stop_reason, start_epoch) | {"epoch_compilations": algo.trace_count} for r in runs
    ]

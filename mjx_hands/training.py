"""The training loop behind ``train.py``: builds the environment and the learner of a
config (:mod:`mjx_hands.train_config`), then only calls the compiled epoch, evaluates,
logs and checkpoints into run directories (:mod:`mjx_hands.run_directory`), stopping on
the budget, a signal or divergence.
"""

from __future__ import annotations

import contextlib
import functools
import math
import os
import resource
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

import jax
import numpy as np

from mjx_hands import checkpoint, cluster, learners, run_directory, train_config
from mjx_hands.run_directory import RunDirectory
from mjx_hands.train_config import TrainConfig, check_population, program_config


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
    single = env_lib.HandInteractionEnv(config.env)
    train_env = env_lib.BatchedEnv(single, config.num_envs // num_devices)
    eval_env = env_lib.BatchedEnv(single, config.eval_envs // num_devices)
    return train_env, eval_env, single


def make_learner(
    config: TrainConfig, devices=None, env_factory=None, population: list | None = None
) -> tuple[learners.Learner, Any]:
    """The learner of ``config`` (its registered ``build``, e.g. DDPG) and its single
    (unbatched) environment.

    ``env_factory(config, num_devices) -> (train_env, eval_env, single_env)`` replaces
    the hand environment (tests train the point-reach task through the same loop).
    ``population``: the configs of every member (``config`` is the first), each with its
    reward variant as data; None trains ``config`` alone.

    A learner holds no run state, so configs that differ only in :data:`RUN_LOOP_FIELDS`
    share one, and with it its compiled programs: a resumed or repeated run in the same
    process compiles nothing again. (JAX's persistent cache cannot stand in: programs with
    host callbacks, as the native physics makes, are never written to it; 3 programs of
    ~10 s each on 2 cores for a small hand run.)
    """
    members = tuple(program_config(c) for c in (population or [config]))
    return _shared_learner(members, tuple(devices) if devices else None, env_factory)


@functools.lru_cache(maxsize=4)
def _shared_learner(members: tuple[TrainConfig, ...], devices, env_factory):
    config = members[0]
    num_devices = len(devices or jax.devices())  # batches are split over every process's
    train_env, eval_env, single = (env_factory or make_envs)(config, num_devices)
    # One physics call steps every member's environments (MuJoCo Warp sizes for them).
    single.reserve(len(members) * max(train_env.num_envs, eval_env.num_envs))
    setup = learners.LearnerSetup(
        config=config,
        train_env=train_env,
        eval_env=eval_env,
        single=single,
        devices=list(devices) if devices else None,
        members=len(members),
        member_info=member_variants(single, list(members)),
    )
    return learners.entry(config.algo).build(setup), single


def run_services(config: TrainConfig, out=None, env_factory=None) -> learners.RunServices:
    """What a standalone learner (``learners.LearnerEntry.run``) gets from the loop:
    its run folder, config.json, environments (``env_factory`` as :func:`make_learner`)
    and logs."""
    return learners.RunServices(
        run_dir=train_config.run_dir_path(config),
        config_json=train_config.config_to_json(config),
        make_envs=env_factory or make_envs,
        metrics_log=run_directory.MetricsLog,
        plot_success=run_directory.plot_success,
        out=out,
    )


# ----------------------------------------------------------------- run
def memory_use() -> dict[str, float]:
    """Host memory now and at its peak, and device memory where the device counts it
    (accelerators; CPU does not), GiB: logged every epoch so growth shows."""
    stats = jax.local_devices()[0].memory_stats() or {}
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


def member_variants(single, configs: list[TrainConfig]) -> dict[str, Any] | None:
    """``member_info`` giving each member its reward variant as data, or None when all
    members use the environment's own variant (``configs[0]``'s)."""
    variant = lambda c: (c.env.reward, c.env.imitation)
    if all(variant(c) == variant(configs[0]) for c in configs):
        return None
    from mjx_hands import env as env_lib

    weights = [single.variant_for(env_lib.reward_weights(c.env)) for c in configs]
    return {"reward_weights": jax.tree.map(lambda *xs: np.stack(xs), *weights)}


def _non_finite(metrics_m: dict[str, float]) -> list[str]:
    """A member's losses that turned non-finite (empty: none)."""
    return sorted(k for k, v in metrics_m.items() if k.startswith("sgd/") and not math.isfinite(v))


def _newly_diverged(
    epoch: int, metrics: list[dict[str, float]], runs: list[RunDirectory], diverged: set[int]
) -> list[int]:
    """Members whose losses or parameters turned non-finite this epoch. A run alone stops
    (TrainingDiverged); in a population the others train on (members share no numbers),
    and the diverged one keeps its last good checkpoint and logs no more. Across
    processes, process 0's verdict holds (the losses are its devices')."""
    verdict = cluster.agree(
        np.array([bool(_non_finite(m)) or m["train/params_finite"] < 1.0 for m in metrics])
    )
    new = []
    for index, (metrics_m, run_m) in enumerate(zip(metrics, runs)):
        bad = _non_finite(metrics_m)
        if index in diverged or not verdict[index]:
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


def run(config: TrainConfig, out=None, env_factory=None) -> dict[str, Any]:
    """Train the project's learner (``ddpg`` or ``td3``) according to ``config``; returns
    a summary (final metrics, paths).

    ``env_factory``: see :func:`make_learner` (default: the hand environment). Brax's
    Learners with their own loop (Brax's SAC and PPO) run through their registered
    ``run`` with :func:`run_services` (train.py picks).
    """
    return run_population([config], out, env_factory)[0]


def run_population(
    configs: list[TrainConfig],
    out=None,
    env_factory=None,
    labels: list[str] | None = None,
) -> list[dict[str, Any]]:
    """Train the runs ``configs`` together as one population (one compiled epoch).

    The configs may differ only in ``MEMBER_FIELDS`` (seed, reward variant, imitation,
    run directory); each member writes an ordinary run directory, and member ``i``
    trains as ``run(configs[i])`` alone would. ``labels`` group members in the progress
    line (e.g. by variant). Returns one summary per member.
    """
    check_population(configs)
    config = configs[0]
    if jax.process_count() > 1 and not learners.entry(config.algo).across_processes:
        raise ValueError(
            f"--algo {config.algo} trains in one process only; across processes: "
            + ", ".join(n for n, e in learners.REGISTRY.items() if e.across_processes)
        )
    launched = time.perf_counter()  # wall clock from here includes the compiles
    runs = [RunDirectory(c) for c in configs]
    for r in runs:
        r.check()
    labels = labels or [str(r.path) for r in runs]
    print(f"building the {config.env.task} environment and learner ...", file=out, flush=True)
    algo, single = make_learner(config, env_factory=env_factory, population=configs)
    print(_setup_line(config, runs, algo, single, launched), file=out, flush=True)
    state = algo.init(np.stack([np.asarray(jax.random.PRNGKey(c.seed)) for c in configs]))
    state, start_epoch = _resume(algo, state, runs, out)
    for r in runs:
        r.open(start_epoch)
    # A resumed run's wall clock continues from where its kept rows end.
    launched -= runs[0].wall_offset()
    started = last_save_time = time.perf_counter()
    stop_reason = "epochs"
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
            if epoch == start_epoch + 1:
                learners.check_epoch_metrics(config.algo, metrics[0])
            diverged.update(_newly_diverged(epoch, metrics, runs, diverged))
            if len(diverged) == len(runs):
                raise TrainingDiverged(f"epoch {epoch}: every member of the population diverged")
            rows = _epoch_rows(config, len(runs), epoch, seconds, time.perf_counter() - launched)
            rows = [
                _with_update_rate(row | m, r.log.rows) for row, m, r in zip(rows, metrics, runs)
            ]
            evaluate = epoch % config.eval_every == 0 or epoch == config.epochs
            elapsed = time.perf_counter() - started
            out_of_time = cluster.agree(
                config.max_minutes is not None and elapsed > 60 * config.max_minutes
            )
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
            rate = len(runs) * rows[0]["time/env_steps_per_second"]
            line = _progress_line(epoch, config.epochs, rate, rows, labels)
            print(f"{line}  left ~{remaining / 60:.0f} min", file=out, flush=True)
            since_save = time.perf_counter() - last_save_time
            if evaluate or out_of_time or cluster.agree(_checkpoint_due(config, epoch, since_save)):
                with interrupts.deferred():
                    _save_members(algo, state, runs, rows, diverged, epoch)
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


def _setup_line(config: TrainConfig, runs: list[RunDirectory], algo, single, launched) -> str:
    """What was built: task, physics, batch, devices, episode, where the runs go."""
    where = (
        runs[0].path
        if len(runs) == 1
        else f"{len(runs)} runs in {os.path.commonpath([str(r.path) for r in runs])}"
    )
    return (
        f"{config.env.task}: {single.describe()}, "
        f"{config.num_envs} envs{' per run' if len(runs) > 1 else ''} on {algo.num_devices} "
        f"{jax.default_backend()} device(s)"
        f"{f' of {jax.process_count()} processes' if jax.process_count() > 1 else ''}, "
        f"episode {single.episode_length} steps, "
        f"run dir {where} ({time.perf_counter() - launched:.0f} s)"
    )


def _resume(algo, state, runs: list[RunDirectory], out) -> tuple[Any, int]:
    """(state, epoch to continue from): the members' common newest checkpoint restored
    into ``state``, or ``state`` and 0 when nothing is resumed."""
    saved = [r.latest_epoch() for r in runs]
    if all(s is None for s in saved):
        return state, 0
    if any(s is None for s in saved):
        missing = [str(r.path) for r, s in zip(runs, saved) if s is None]
        raise checkpoint.CheckpointError(f"--resume: no checkpoint in {', '.join(missing)}")
    start_epoch = min(saved)  # members save together; a crash mid-save leaves some ahead
    for r in runs:  # ... whose newer checkpoints the resumed run will write again
        checkpoint.discard_after(r.checkpoints, start_epoch)
        checkpoint.discard_after(r.best_dir, start_epoch)
    # Shapes only: a concrete state would be laid out (across processes: copied) to say them.
    like = jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype), state)
    trees = [
        r.restore(algo, like, i, start_epoch, verified=s == start_epoch)
        for i, (r, s) in enumerate(zip(runs, saved, strict=True))
    ]
    print(f"resumed from epoch {start_epoch}", file=out, flush=True)
    return algo.from_checkpoint_trees(trees, state), start_epoch


def _epoch_rows(
    config: TrainConfig, members: int, epoch: int, seconds: float, wall: float
) -> list[dict[str, float]]:
    """Each member's timing and memory columns of an epoch's metrics row."""
    steps = config.num_envs * config.ddpg.unroll_length * config.ddpg.iterations_per_epoch
    row = {
        "epoch": float(epoch),
        "time/epoch_seconds": seconds,
        "time/env_steps_per_second": steps / seconds,  # this run's
        "time/wall_seconds": wall,
    }
    if members > 1:  # what the machine did: every member's steps
        row["time/population_env_steps_per_second"] = members * steps / seconds
    return [row | memory_use()] * members


def _with_update_rate(row: dict[str, float], logged: list[dict[str, float]]) -> dict[str, float]:
    """``row`` with the epoch's critic updates per second, counted by the learner itself
    (none during the replay warm-up), when the run's previous row is the epoch before."""
    previous = logged[-1] if logged else {"epoch": 0.0, "train/updates": 0.0}
    if "train/updates" not in row or previous.get("epoch") != row["epoch"] - 1:
        return row
    done = float(row["train/updates"]) - previous["train/updates"]
    return row | {"time/updates_per_second": done / row["time/epoch_seconds"]}


def _checkpoint_due(config: TrainConfig, epoch: int, since_save: float) -> bool:
    """Whether the epoch count or the wall clock since the last save asks for one."""
    if epoch % config.checkpoint_every == 0:
        return True
    return config.checkpoint_minutes is not None and since_save > 60 * config.checkpoint_minutes


def _save_members(algo, state, runs: list[RunDirectory], rows, diverged: set[int], epoch: int):
    """Every healthy member's checkpoint of ``epoch``, and its policy in best/ when this
    epoch's evaluation is its best so far."""
    for i, (r, row) in enumerate(zip(runs, rows)):
        if i in diverged:
            continue
        r.save(algo.checkpoint_tree(state, r.config.save_replay, i), epoch, algo.num_devices)
        if "eval/success" in row:
            policy = functools.partial(algo.policy_tree, state, i)
            r.save_if_best(policy, epoch, row, algo.num_devices)

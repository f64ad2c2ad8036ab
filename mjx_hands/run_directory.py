"""A run directory: ``config.json``, ``metrics.csv`` (one row per epoch; evaluation
columns filled every ``eval_every`` epochs) with TensorBoard event files beside it,
``checkpoints/`` (Orbax; the latest few, to resume from), ``best/`` (the policy of the
best evaluation so far) and ``success.png``. The learner decides what a checkpoint holds;
this module decides where it goes and when a run may start, resume or keep a best."""

from __future__ import annotations

import csv
import json
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from mjx_hands import checkpoint, cluster, train_config
from mjx_hands.env_config import partner_models

BEST_DIR = "best"  # run_dir/best: the learner of the best evaluation, for evaluate --best


class MetricsLog:
    """metrics.csv + TensorBoard events in the run directory; appends on resume.
    ``write=False`` keeps the rows in memory only (the processes of a run spread over
    several, but the first: ``mjx_hands.cluster``)."""

    def __init__(self, run_dir: Path, write: bool = True):
        self.path = run_dir / "metrics.csv"
        self.write = write
        self.rows: list[dict[str, float]] = []
        if self.path.exists():
            with self.path.open() as f:
                self.rows = [
                    {k: float(v) for k, v in r.items() if v not in ("", None) and k is not None}
                    for r in csv.DictReader(f)
                ]
        self.tb = None
        if write:
            from tensorboardX import SummaryWriter

            self.tb = SummaryWriter(str(run_dir / "tensorboard"))

    def append(self, row: dict[str, float]) -> None:
        self.rows.append(row)
        if not self.write:
            return
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


def eval_rank(row: dict[str, float]) -> tuple[float, float, float]:
    """Order of evaluations for the best policy: success at the end of the episode (the
    authors' metric), then success at some step, then the return."""
    return (row["eval/success_final"], row["eval/success"], row["eval/episode_return"])


class RunDirectory:
    """One run's folder: config.json, metrics.csv + TensorBoard, checkpoints/, best/,
    success.png. A member of a population has one like any run (``evaluate`` opens it)."""

    def __init__(self, config: train_config.TrainConfig):
        self.config = config
        self.path = train_config.run_dir_path(config)
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
            train_config.check_resumable(
                train_config.read_config_json(self.config_path), self.config, self.path
            )
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

    def restore(self, algo, like, index: int, epoch: int, verified: bool = False) -> dict[str, Any]:
        """Member ``index``'s checkpoint tree of ``epoch`` (the learner ``algo``'s layout,
        shaped like the state ``like``'s). ``verified``: :meth:`latest_epoch` returned ``epoch``, so its digest
        was checked (hashing reads every byte of the step: a replay buffer is GBs)."""
        num_devices = algo.num_devices
        meta = checkpoint.read_metadata(self.checkpoints, epoch, verified=verified)
        saved_devices = int(meta.get("num_devices", 1))
        if saved_devices != num_devices:
            raise checkpoint.CheckpointError(
                f"--resume: {self.path} was trained on {saved_devices} device(s), this run "
                f"has {num_devices} (over all its processes); resume with {saved_devices} (CPU: XLA_FLAGS="
                f"--xla_force_host_platform_device_count={saved_devices})"
            )
        # The checkpoint's own setting says whether it holds the replay buffer.
        saved_replay = meta["config"]["save_replay"]
        layout = algo.checkpoint_tree(like, saved_replay, index)
        # Other partner models (a curriculum's next stage) keep learner and replay; the
        # episodes in flight start afresh, also where their state's layout would fit: they
        # were drawn against the old models, and the new stage's begin with it.
        saved_env = train_config.config_from_json(meta["config"]).env
        new_partner = partner_models(saved_env) != partner_models(self.config.env)
        if new_partner:
            layout = {k: v for k, v in layout.items() if k != "env_state"}
        tree, _ = checkpoint.restore(
            self.checkpoints,
            layout,
            epoch,
            partial=new_partner,
            verified=True,  # checked by read_metadata above or by latest_epoch
        )
        return tree

    def open(self, start_epoch: int) -> None:
        """Write config.json (the run is known to start) and open the metrics log, keeping
        the rows up to ``start_epoch``."""
        primary = cluster.is_primary()
        if primary:
            self.path.mkdir(parents=True, exist_ok=True)
            self.config_path.write_text(
                json.dumps(train_config.config_to_json(self.config), indent=2)
            )
        self.log = MetricsLog(self.path, write=primary)
        self.log.rows = [r for r in self.log.rows if r.get("epoch", 0) <= start_epoch]
        self.best = max(
            (r for r in self.log.rows if "eval/success" in r), key=eval_rank, default=None
        )
        if self.best is not None and not self._best_saved(int(self.best["epoch"])):
            self.best = None  # killed while saving it: the next evaluation saves a best
        self.last_saved = start_epoch

    def _best_saved(self, epoch: int) -> bool:
        """Whether best/ holds an intact policy of ``epoch``; a damaged one is set aside."""
        saved = epoch in checkpoint.steps(self.best_dir)
        intact = saved and checkpoint.damage(self.best_dir, epoch) is None
        saved, intact = cluster.agree(np.array([saved, intact]))  # process 0 judges for all
        if intact or not saved:
            return bool(intact)
        checkpoint.discard_after(self.best_dir, epoch - 1)
        return False

    def wall_offset(self) -> float:
        """Seconds a resumed run had already run (its kept rows' wall clock)."""
        return self.log.rows[-1].get("time/wall_seconds", 0.0) if self.log.rows else 0.0

    def metadata(self, epoch: int, num_devices: int) -> dict[str, Any]:
        return {
            "epoch": epoch,
            "config": train_config.config_to_json(self.config),
            "num_devices": num_devices,
        }

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
        if not cluster.is_primary():
            return
        env = self.config.env
        title = f"{env.task} ({self.config.algo}, {env.reward}"
        title += ")" if env.imitation else ", no imitation)"
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

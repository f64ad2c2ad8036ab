"""Orbax checkpoints of a training run: every array needed to continue, plus JSON metadata.

A checkpoint holds the trainer state as a flat mapping ``leaf_<i> -> array`` (host
numpy, the device axis kept) and a JSON record of the run config, the epoch, and the
path, shape and dtype of every leaf. Restoring checks that record against the state
the current config builds, so a checkpoint of another task, network size, batch or
device count is refused with a message naming the first mismatch instead of failing
deep inside Orbax. Orbax writes each step to a temporary folder and renames it when
complete, so a crash during a save leaves the previous checkpoint intact.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import jax
import numpy as np
import orbax.checkpoint as ocp


class CheckpointError(RuntimeError):
    """A checkpoint is missing, unreadable, or does not fit the current configuration."""


def _leaves(tree) -> tuple[list[str], list[np.ndarray], Any]:
    with_path, treedef = jax.tree_util.tree_flatten_with_path(tree)
    paths = [jax.tree_util.keystr(p) for p, _ in with_path]
    return paths, [np.asarray(x) for _, x in with_path], treedef


def _manager(directory: Path, max_to_keep: int = 3, create: bool = False) -> ocp.CheckpointManager:
    options = ocp.CheckpointManagerOptions(max_to_keep=max_to_keep, create=create)
    return ocp.CheckpointManager(Path(directory).absolute(), options=options)


def save(
    directory: Path, step: int, state, metadata: dict[str, Any], max_to_keep: int = 3
) -> None:
    """Write ``state`` (any pytree of arrays) and ``metadata`` (JSON-able) as ``step``;
    the oldest steps beyond ``max_to_keep`` are deleted once it is complete."""
    paths, leaves, _ = _leaves(jax.device_get(state))
    record = dict(metadata)
    record["leaves"] = [
        {"path": p, "shape": list(x.shape), "dtype": str(x.dtype)} for p, x in zip(paths, leaves)
    ]
    # Orbax refuses empty arrays (MJX data has some); their shape in the record suffices.
    arrays = {f"leaf_{i:05d}": x for i, x in enumerate(leaves) if x.size}
    with _manager(directory, max_to_keep, create=True) as manager:
        manager.save(
            step,
            args=ocp.args.Composite(
                state=ocp.args.StandardSave(arrays), metadata=ocp.args.JsonSave(record)
            ),
        )
        manager.wait_until_finished()


def latest_step(directory: Path) -> int | None:
    """The newest complete checkpoint step in ``directory``, or None."""
    directory = Path(directory)
    if not directory.is_dir():
        return None
    with _manager(directory) as manager:
        return manager.latest_step()


def read_metadata(directory: Path, step: int | None = None) -> dict[str, Any]:
    """The JSON record of checkpoint ``step`` (default: the latest)."""
    step = _resolve_step(directory, step)
    with _manager(directory) as manager:
        restored = manager.restore(step, args=ocp.args.Composite(metadata=ocp.args.JsonRestore()))
    return dict(restored["metadata"])


def restore(
    directory: Path, like, step: int | None = None, partial: bool = False
) -> tuple[Any, dict[str, Any]]:
    """Load checkpoint ``step`` (default: latest) into the structure of ``like``.

    ``like`` is a state built from the current config (its values are ignored); the
    checkpoint must have the same leaves with the same shapes and dtypes. With
    ``partial``, ``like`` may be a part of what was saved (e.g. only the learner of a
    whole training state): its leaves are found by path.
    Returns the restored state (host numpy leaves) and the metadata.
    """
    step = _resolve_step(directory, step)
    metadata = read_metadata(directory, step)
    with_path, treedef = jax.tree_util.tree_flatten_with_path(like)
    paths = [jax.tree_util.keystr(p) for p, _ in with_path]
    leaves = [
        jax.ShapeDtypeStruct(
            np.shape(x), np.asarray(x).dtype if not hasattr(x, "dtype") else x.dtype
        )
        for _, x in with_path
    ]
    saved = metadata.get("leaves", [])
    if partial:
        index_of = {entry["path"]: i for i, entry in enumerate(saved)}
        missing = [p for p in paths if p not in index_of]
        if missing:
            raise CheckpointError(
                f"checkpoint {directory} step {step} lacks {missing[0]} (and "
                f"{len(missing) - 1} more arrays) that the current configuration needs"
            )
        indices = [index_of[p] for p in paths]
    elif len(saved) != len(paths):
        raise CheckpointError(
            f"checkpoint {directory} step {step} has {len(saved)} arrays but the current "
            f"configuration needs {len(paths)}: it was written by an incompatible config "
            "or an older version (evaluate still opens its policy)"
        )
    else:
        indices = list(range(len(paths)))
    for i, path, leaf in zip(indices, paths, leaves):
        entry = saved[i]
        if (
            entry["path"] != path
            or tuple(entry["shape"]) != tuple(leaf.shape)
            or (entry["dtype"] != str(leaf.dtype))
        ):
            raise CheckpointError(
                f"checkpoint {directory} step {step} is incompatible with the current "
                f"configuration: it holds {entry['path']} {entry['dtype']}{tuple(entry['shape'])}, "
                f"the config expects {path} {leaf.dtype}{tuple(leaf.shape)}"
            )
    wanted = [(i, leaf) for i, leaf in zip(indices, leaves) if np.prod(leaf.shape)]
    abstract = {f"leaf_{i:05d}": jax.ShapeDtypeStruct(leaf.shape, leaf.dtype) for i, leaf in wanted}
    with _manager(directory) as manager:
        args = ocp.args.StandardRestore(abstract)
        if partial:  # read only the arrays it names
            args = ocp.args.PyTreeRestore(
                item=abstract,
                restore_args=jax.tree.map(lambda _: ocp.RestoreArgs(restore_type=np.ndarray), abstract),
                partial_restore=True,
            )
        restored = manager.restore(step, args=ocp.args.Composite(state=args))
    arrays = [
        np.asarray(restored["state"][f"leaf_{i:05d}"])
        if np.prod(leaf.shape)
        else np.zeros(leaf.shape, leaf.dtype)
        for i, leaf in zip(indices, leaves)
    ]
    return jax.tree_util.tree_unflatten(treedef, arrays), metadata


def discard_after(directory: Path, step: int) -> list[int]:
    """Delete the checkpoints of ``directory`` newer than ``step`` (a population resumes
    from the epoch all its members saved); returns the deleted steps."""
    directory = Path(directory)
    if not directory.is_dir():
        return []
    with _manager(directory) as manager:
        newer = [s for s in manager.all_steps() if s > step]
        for s in newer:
            manager.delete(s)
    return newer


def _resolve_step(directory: Path, step: int | None) -> int:
    if not Path(directory).is_dir():
        raise CheckpointError(f"no checkpoint found in {directory} (no such folder)")
    if step is None:
        step = latest_step(directory)
        if step is None:
            raise CheckpointError(f"no checkpoint found in {directory}")
    return step

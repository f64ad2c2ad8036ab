"""Orbax checkpoints of a training run: every array needed to continue, plus JSON metadata.

A checkpoint holds the trainer state as a flat mapping ``leaf_<i> -> array`` (host
numpy, the device axis kept) and a JSON record of the run config, the epoch, and the
path, shape and dtype of every leaf. Restoring checks that record against the state
the current config builds, so a checkpoint of another task, network size, batch or
device count is refused with a message naming the first mismatch instead of failing
deep inside Orbax.

Integrity: Orbax writes each step to a temporary folder and renames it when complete;
once it has, :func:`save` writes ``digest.json`` (the SHA-256 of every file) into the
step, last. A step is *intact* when every file matches its digest. Without a step
named, reading takes the newest intact step, with a :class:`CheckpointWarning` naming
what is wrong with each newer one (truncated, altered or missing file, unfinished
save); a named step that is not intact is refused with the same message. Steps written
before digests existed (no ``format`` in their record) are read unverified.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import warnings
from pathlib import Path
from typing import Any

import jax
import numpy as np
import orbax.checkpoint as ocp

from mjx_hands import cluster


class CheckpointError(RuntimeError):
    """A checkpoint is missing, unreadable, or does not fit the current configuration."""


class CheckpointWarning(UserWarning):
    """A damaged or unfinished checkpoint was skipped for an older, intact one."""


FORMAT = 2
"""Written into every record; steps with a format are verified against their digest."""
DIGEST_FILE = "digest.json"
METADATA_FILE = Path("metadata") / "metadata"  # Orbax's JsonSave of the record


def _leaves(tree) -> tuple[list[str], list[Any], Any]:
    """Paths and host arrays of ``tree``; arrays split over several processes (a run
    spread over hosts, ``mjx_hands.cluster``) stay as they are: each process writes its
    part of them."""
    with_path, treedef = jax.tree_util.tree_flatten_with_path(tree)
    paths = [jax.tree_util.keystr(p) for p, _ in with_path]
    return paths, [_host(x) for _, x in with_path], treedef


def _host(x):
    if isinstance(x, jax.Array) and not x.is_fully_addressable:
        return x
    return np.asarray(jax.device_get(x))


def _drop_metadata_notice(record: logging.LogRecord) -> bool:
    """Keep Orbax's notice that a registry without jax.Array skips array metadata (every
    restore with the registry below logs it; arrays are saved as NumPy on purpose) out of
    users' terminals; everything else it logs passes."""
    return not record.getMessage().startswith("No jax.Array in TypeHandlerRegistry")


logging.getLogger("absl").addFilter(_drop_metadata_notice)


def _manager(directory: Path, max_to_keep: int = 3, create: bool = False) -> ocp.CheckpointManager:
    options = ocp.CheckpointManagerOptions(max_to_keep=max_to_keep, create=create)
    # Uncompressed zarr3 arrays: a CPU-preset member state (250 MB, mostly replay) saves
    # in 0.73 s instead of 1.12 s (zstd, zarr2; median of 7 on 2 quiet cores, measured
    # when the format was chosen, no record kept) for 29 % more disk, which matters now that every epoch checkpoints. Older
    # compressed checkpoints still restore: the arrays' own metadata names their codec.
    # Saves wait until written, so Orbax's defensive copy of every host array (1.25 s of a
    # 3.4 s save of that state, profiled) is not needed.
    arrays = ocp.type_handlers.create_type_handler_registry(
        (np.ndarray, ocp.type_handlers.NumpyHandler(deepcopy_host_arrays=False)),
        (jax.Array, ocp.type_handlers.ArrayHandler()),  # split over processes
    )
    handlers = {
        "state": ocp.PyTreeCheckpointHandler(
            use_compression=False, use_zarr3=True, type_handler_registry=arrays
        ),
        "metadata": ocp.JsonCheckpointHandler(),
    }
    return ocp.CheckpointManager(
        Path(directory).absolute(), options=options, item_handlers=handlers
    )


def save(directory: Path, step: int, state, metadata: dict[str, Any], max_to_keep: int = 3) -> None:
    """Write ``state`` (any pytree of arrays) and ``metadata`` (JSON-able) as ``step``;
    the oldest steps beyond ``max_to_keep`` are deleted once it is complete."""
    paths, leaves, _ = _leaves(state)
    record = dict(metadata) | {"format": FORMAT}
    record["leaves"] = [
        {"path": p, "shape": list(x.shape), "dtype": str(x.dtype)} for p, x in zip(paths, leaves)
    ]
    # Orbax refuses empty arrays (MJX data has some); their shape in the record suffices.
    arrays = {f"leaf_{i:05d}": x for i, x in enumerate(leaves) if x.size}
    with _manager(directory, max_to_keep, create=True) as manager:
        manager.save(
            step,
            args=ocp.args.Composite(
                state=ocp.args.PyTreeSave(arrays), metadata=ocp.args.JsonSave(record)
            ),
        )
        manager.wait_until_finished()
    if cluster.is_primary():  # every process saved its part (Orbax waited for all)
        _write_digest(Path(directory).absolute() / str(step))
    cluster.barrier(f"digest {directory} {step}")


def _file_digests(step_dir: Path) -> dict[str, str]:
    """SHA-256 of every file under ``step_dir`` but the digest itself, by relative path."""
    digests = {}
    for file in sorted(step_dir.rglob("*")):
        if file.is_file() and file.name != DIGEST_FILE:
            with open(file, "rb") as f:
                digests[file.relative_to(step_dir).as_posix()] = hashlib.file_digest(
                    f, "sha256"
                ).hexdigest()
    return digests


def _write_digest(step_dir: Path) -> None:
    """Write the step's digest last, atomically: its presence marks the save complete."""
    tmp = step_dir / (DIGEST_FILE + ".tmp")
    tmp.write_text(json.dumps({"sha256": _file_digests(step_dir)}, indent=1))
    os.replace(tmp, step_dir / DIGEST_FILE)


def steps(directory: Path) -> list[int]:
    """Every finalised step in ``directory`` (intact or not), oldest first. Unfinished
    Orbax saves (temporary folders) are not steps."""
    directory = Path(directory)
    if not directory.is_dir():
        return []
    return sorted(int(p.name) for p in directory.iterdir() if p.is_dir() and p.name.isdigit())


def damage(directory: Path, step: int) -> str | None:
    """What is wrong with checkpoint ``step`` (None: intact, or written before digests).

    Checks every file against the step's digest: missing, truncated or altered files,
    and a save that did not finish (a record but no digest)."""
    step_dir = Path(directory) / str(step)
    if not step_dir.is_dir():
        return f"{step_dir} does not exist"
    digest_file = step_dir / DIGEST_FILE
    if not digest_file.is_file():
        try:
            record = json.loads((step_dir / METADATA_FILE).read_text())
        except (OSError, ValueError) as err:
            return f"{step_dir / METADATA_FILE} is unreadable ({err}) and there is no digest"
        if isinstance(record, dict) and "format" not in record:
            return None  # written before digests: nothing to verify against
        return f"{step_dir} is unfinished: its save stopped before the digest was written"
    try:
        expected = json.loads(digest_file.read_text())["sha256"]
    except (OSError, ValueError, KeyError, TypeError) as err:
        return f"{digest_file} is unreadable ({err})"
    actual = _file_digests(step_dir)
    for name, digest in expected.items():
        if name not in actual:
            return f"{step_dir / name} is missing"
        if actual[name] != digest:
            size = (step_dir / name).stat().st_size
            return f"{step_dir / name} is damaged ({size} bytes, content differs from its digest)"
    return None


def latest_step(directory: Path) -> int | None:
    """The newest intact checkpoint step in ``directory``; None when it has no steps.

    Newer damaged or unfinished steps are skipped with a :class:`CheckpointWarning`;
    raises CheckpointError when there are steps but none is intact.
    """
    problems = []
    for step in reversed(steps(directory)):
        problem = damage(directory, step)
        if problem is None:
            if problems:
                warnings.warn(
                    f"skipping {len(problems)} damaged checkpoint(s): {'; '.join(problems)}; "
                    f"using step {step}",
                    CheckpointWarning,
                    stacklevel=2,
                )
            return step
        problems.append(f"step {step}: {problem}")
    if problems:
        raise CheckpointError(f"no intact checkpoint in {directory}: {'; '.join(problems)}")
    return None


def resolve_step(directory: Path, step: int | None = None) -> int:
    """``step`` after checking it is intact, or the newest intact step when None."""
    if not Path(directory).is_dir():
        raise CheckpointError(f"no checkpoint found in {directory} (no such folder)")
    if step is None:
        step = latest_step(directory)
        if step is None:
            raise CheckpointError(f"no checkpoint found in {directory}")
        return step
    if step not in steps(directory):
        raise CheckpointError(
            f"no checkpoint step {step} in {directory}; it holds {steps(directory) or 'none'}"
        )
    problem = damage(directory, step)
    if problem is not None:
        raise CheckpointError(f"checkpoint step {step} cannot be used: {problem}")
    return step


def read_metadata(
    directory: Path, step: int | None = None, *, verified: bool = False
) -> dict[str, Any]:
    """The JSON record of checkpoint ``step`` (default: the newest intact one).
    ``verified``: ``step`` came from :func:`resolve_step`, whose digest check (which reads
    every byte of the step) need not run again."""
    if not (verified and step is not None):
        step = resolve_step(directory, step)
    return _read_record(directory, step)


def _read_record(directory: Path, step: int) -> dict[str, Any]:
    """The JSON record of a step already verified (hashing a step reads all its bytes)."""
    try:
        with _manager(directory) as manager:
            restored = manager.restore(
                step, args=ocp.args.Composite(metadata=ocp.args.JsonRestore())
            )
    except Exception as err:  # Orbax/JSON errors name neither the run nor the file
        raise CheckpointError(
            f"cannot read {Path(directory) / str(step) / METADATA_FILE}: {err}"
        ) from err
    return dict(restored["metadata"])


def restore(
    directory: Path, like, step: int | None = None, partial: bool = False, *, verified: bool = False
) -> tuple[Any, dict[str, Any]]:
    """Load checkpoint ``step`` (default: latest) into the structure of ``like``.

    ``like`` is a state built from the current config (its values are ignored); the
    checkpoint must have the same leaves with the same shapes and dtypes. With
    ``partial``, ``like`` may be a part of what was saved (e.g. only the learner of a
    whole training state): its leaves are found by path.
    ``verified``: as in :func:`read_metadata`.
    Returns the restored state (host numpy leaves) and the metadata.
    """
    if not (verified and step is not None):
        step = resolve_step(directory, step)
    metadata = _read_record(directory, step)
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
    args = ocp.args.PyTreeRestore(
        item=abstract,
        restore_args=jax.tree.map(lambda _: ocp.RestoreArgs(restore_type=np.ndarray), abstract),
        partial_restore=partial,  # read only the arrays it names
    )
    try:
        with _manager(directory) as manager:
            restored = manager.restore(step, args=ocp.args.Composite(state=args))
    except Exception as err:  # e.g. a step written before digests, damaged since
        raise CheckpointError(
            f"cannot read the arrays of {Path(directory) / str(step)}: {err}"
        ) from err
    arrays = [
        np.asarray(restored["state"][f"leaf_{i:05d}"])
        if np.prod(leaf.shape)
        else np.zeros(leaf.shape, leaf.dtype)
        for i, leaf in zip(indices, leaves)
    ]
    return jax.tree_util.tree_unflatten(treedef, arrays), metadata


def discard_after(directory: Path, step: int) -> list[int]:
    """Remove the checkpoints of ``directory`` newer than ``step`` (a population resumes
    from the epoch all its members saved; a run from its newest intact step). Intact
    ones are deleted (they will be written again); damaged ones are moved to
    ``<directory>.damaged/`` for inspection. Returns the removed steps."""
    directory = Path(directory)
    newer = [s for s in steps(directory) if s > step]
    cluster.barrier(f"read {directory}")  # no process may still be hashing what goes
    for s in newer if cluster.is_primary() else []:  # the folder all processes share
        if damage(directory, s) is None:
            shutil.rmtree(directory / str(s))
        else:
            aside = directory.with_name(directory.name + ".damaged")
            aside.mkdir(exist_ok=True)
            shutil.move(directory / str(s), aside / f"{s}-{os.getpid()}")
    cluster.barrier(f"discard {directory} {step}")
    return newer

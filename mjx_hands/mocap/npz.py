"""The project's own demonstration files, ``mocap_data/<task>.npz`` (schema in
``mocap_data/README.md``): writer, strict reader and :func:`load_synthetic`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjx_hands.mocap.demonstration import (
    SYNTHETIC_PATH,
    Demonstration,
    MocapError,
    build_demonstration,
    check_bounds,
    check_dtype,
    check_shape,
    check_task,
    matrix_to_quat_wxyz,
    quat_wxyz_to_matrix,
    vector_norm,
)
from mjx_hands.shadow_hand import HAND_JOINTS

SCHEMA_VERSION = 2
"""Version of the ``mocap_data/<task>.npz`` layout (see mocap_data/README.md). Version 2
added the optional target motion arrays; version-1 files are read as targets that
neither turn nor record their position."""
READABLE_VERSIONS = (1, 2)


# ------------------------------------------------------------ the project's own files
_NPZ_PER_DEMO = ("names", "fps", "num_frames", "contact_begin", "contact_end")
_NPZ_PER_FRAME = {
    "actor_joints": (len(HAND_JOINTS),),
    "target_joints": (len(HAND_JOINTS),),
    "actor_palm_pos": (3,),
    "actor_palm_quat": (4,),
}
_NPZ_OPTIONAL = {  # the target's own motion (schema 2): per frame, absent -> not recorded
    "target_palm_quat": (4,),
    "target_palm_pos": (3,),
}
_NPZ_DTYPES = {
    "schema_version": "int",
    "task": "str",
    "names": "str",
    "fps": "float",
    "num_frames": "int",
    "contact_begin": "int",
    "contact_end": "int",
    **{key: "float" for key in (*_NPZ_PER_FRAME, *_NPZ_OPTIONAL)},
}
"""Every array of the npz layout and the dtype kind it must have (see :func:`check_dtype`)."""


def demos_to_arrays(demos: list[Demonstration]) -> dict[str, np.ndarray]:
    """The npz layout of mocap_data/<task>.npz (schema in mocap_data/README.md).

    Frames of all demonstrations are concatenated; per-frame arrays are float32.
    """
    if not demos:
        raise MocapError("no demonstrations to store")
    task = demos[0].task
    if any(d.task != task for d in demos):
        raise MocapError("all demonstrations of one file must share a task")
    cat = lambda f: np.concatenate([f(d) for d in demos]).astype(np.float32)
    recorded = [d.target_palm_pos is not None for d in demos]
    if any(recorded) and not all(recorded):
        raise MocapError(
            "demonstrations of one file must all record the target palm position or none "
            f"(recorded by {sum(recorded)} of {len(demos)})"
        )
    optional = {"target_palm_pos": cat(lambda d: d.target_palm_pos)} if all(recorded) else {}
    return optional | {
        "schema_version": np.int64(SCHEMA_VERSION),
        "task": np.str_(task),
        "names": np.array([d.name for d in demos]),
        "fps": np.array([d.fps for d in demos], np.float64),
        "num_frames": np.array([d.num_frames for d in demos], np.int64),
        "contact_begin": np.array([d.contact_begin for d in demos], np.int64),
        "contact_end": np.array([d.contact_end for d in demos], np.int64),
        "actor_joints": cat(lambda d: d.actor_joints),
        "target_joints": cat(lambda d: d.target_joints),
        "actor_palm_pos": cat(lambda d: d.actor_points[:, 0]),
        "actor_palm_quat": cat(lambda d: matrix_to_quat_wxyz(d.actor_palm_rot)),
        "target_palm_quat": cat(lambda d: matrix_to_quat_wxyz(d.target_palm_rot)),
    }


def save_npz(demos: list[Demonstration], file: str | Path) -> None:
    """Write demonstrations of one task to ``file`` (compressed npz, no pickles)."""
    np.savez_compressed(file, **demos_to_arrays(demos))


def _npz_frame_checks(where: str, arrays: dict[str, np.ndarray]) -> None:
    """Plausibility bounds on every frame of the per-frame arrays (NaN/inf included)."""
    for key, quantity, columns in [
        ("actor_joints", "angle", HAND_JOINTS),
        ("target_joints", "angle", HAND_JOINTS),
        ("actor_palm_pos", "length", None),
        ("actor_palm_quat", "norm", None),
        ("target_palm_quat", "norm", None),
        ("target_palm_pos", "length", None),
    ]:
        if key not in arrays:
            continue
        values = arrays[key] if quantity == "angle" else vector_norm(arrays[key])
        check_bounds(where, key, quantity, values, columns=columns, at="row")


def demos_from_arrays(arrays, task: str, source: str, where: str = "arrays") -> list[Demonstration]:
    """Inverse of demos_to_arrays (fingertips recomputed by FK). ``where`` names the file.

    Checks every array's presence, dtype and shape, the values of every frame against the
    plausibility bounds, and that there is at least one demonstration; unknown arrays are
    an error too (nothing in a file is silently ignored). Raises MocapError naming
    ``where`` and the array.
    """
    missing = [key for key in _NPZ_DTYPES if key not in arrays and key not in _NPZ_OPTIONAL]
    if missing:
        raise MocapError(f"{where}: missing array {missing[0]!r}")
    unknown = sorted(set(arrays) - set(_NPZ_DTYPES))
    if unknown:
        raise MocapError(
            f"{where}: unknown array {unknown[0]!r} (got {len(arrays)} arrays, expected "
            f"only {', '.join(_NPZ_DTYPES)} of schema {SCHEMA_VERSION})"
        )
    a = {key: np.asarray(arrays[key]) for key in _NPZ_DTYPES if key in arrays}
    for key, kind in _NPZ_DTYPES.items():
        if key in a:
            check_dtype(where, key, a[key], kind)
    check_shape(where, "schema_version", a["schema_version"], ())
    version = int(a["schema_version"])
    if version not in READABLE_VERSIONS:
        raise MocapError(f"{where}: schema_version {version}, expected one of {READABLE_VERSIONS}")
    newer = sorted(key for key in _NPZ_OPTIONAL if key in a)
    if version < 2 and newer:
        raise MocapError(f"{where}: array {newer[0]!r} needs schema_version 2, got {version}")
    check_shape(where, "task", a["task"], ())
    if str(a["task"]) != task:
        raise MocapError(f"{where}: holds task {str(a['task'])!r}, expected {task!r}")
    if a["num_frames"].ndim != 1:
        raise MocapError(f"{where}: num_frames must have shape (N,), got {a['num_frames'].shape}")
    n = len(a["num_frames"])
    for key in _NPZ_PER_DEMO:
        check_shape(where, key, a[key], (n,))
    if n == 0:
        raise MocapError(f"{where}: no demonstrations (got 0, expected at least 1)")
    lengths = [int(x) for x in a["num_frames"]]  # Python ints: no overflow in the sum
    if min(lengths) < 2:
        i = int(np.argmin(lengths))
        raise MocapError(
            f"{where}: num_frames of demonstration {i} too small (got {lengths[i]}, expected >= 2)"
        )
    total = sum(lengths)
    for key, tail in (_NPZ_PER_FRAME | _NPZ_OPTIONAL).items():
        if key in a:
            check_shape(where, key, a[key], (total, *tail))
    _npz_frame_checks(where, a)
    bounds = np.concatenate([[0], np.cumsum(lengths)])
    demos = []
    for i in range(n):
        f = slice(int(bounds[i]), int(bounds[i + 1]))
        quat = np.asarray(a["actor_palm_quat"][f], np.float64)
        turn = a.get("target_palm_quat")
        turn = None if turn is None else quat_wxyz_to_matrix(np.asarray(turn[f], np.float64))
        path = a.get("target_palm_pos")
        path = None if path is None else np.asarray(path[f], np.float64)
        try:
            demo = build_demonstration(
                task=task,
                name=str(a["names"][i]),
                source=source,
                fps=float(a["fps"][i]),
                actor_joints=a["actor_joints"][f],
                target_joints=a["target_joints"][f],
                actor_palm_pos=a["actor_palm_pos"][f],
                actor_palm_rot=quat_wxyz_to_matrix(quat),
                contact_begin=int(a["contact_begin"][i]),
                contact_end=int(a["contact_end"][i]),
                target_palm_rot=turn,
                target_palm_pos=path,
            )
        except MocapError as e:  # Demonstration.validate names the demonstration only
            raise MocapError(f"{where}: {e}") from e
        demos.append(demo)
    return demos


def _read_npz(file: Path) -> dict[str, np.ndarray]:
    """Every array of the npz archive ``file``; MocapError naming the file (and array) for
    any damage: NumPy and zipfile raise many types (BadZipFile, EOFError, zlib.error...)."""
    try:
        archive = np.load(file, allow_pickle=False)
    except Exception as e:
        raise MocapError(f"{file}: cannot read the archive ({type(e).__name__}: {e})") from e
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise MocapError(f"{file}: not an npz archive (got a single {type(archive).__name__})")
    with archive:
        arrays = {}
        for key in archive.files:
            try:
                arrays[key] = archive[key]
            except Exception as e:
                raise MocapError(
                    f"{file}: cannot read array {key!r} ({type(e).__name__}: {e})"
                ) from e
    return arrays


def load_synthetic(task: str, path: str | Path | None = None) -> list[Demonstration]:
    """The project's demonstrations of one task from ``<path>/<task>.npz``."""
    check_task(task)
    file = Path(path if path is not None else SYNTHETIC_PATH) / f"{task}.npz"
    if not file.is_file():
        raise MocapError(
            f"missing synthetic demonstrations {file}; run `python -m mjx_hands.synthetic_demos`"
        )
    return demos_from_arrays(_read_npz(file), task, "synthetic", where=str(file))

"""Human demonstrations of the three hand interactions, in the target hand's palm frame.

Two sources produce the same :class:`Demonstration` (host-side NumPy):

* ``"optitrack"`` -- the authors' released OptiTrack arrays (``../shared/mocap/
  drl_handshake`` beside the repository; never copied into it), read by
  :func:`load_optitrack`;
* ``"synthetic"`` -- the project's own demonstrations in ``mocap_data/`` (written by
  ``python -m mjx_hands.synthetic_demos``), read by :func:`load_synthetic`.

:func:`load_demonstrations` is what the environment calls. The modules:
:mod:`~mjx_hands.mocap.demonstration` (the type, checks, geometry),
:mod:`~mjx_hands.mocap.release` (the authors' recordings) and
:mod:`~mjx_hands.mocap.npz` (the project's files); this package re-exports their API.
A lab's own takes come in through :mod:`~mjx_hands.mocap.takes` (BVH:
:mod:`~mjx_hands.mocap.bvh`, Motive CSV: :mod:`~mjx_hands.mocap.motive`, mapped by
:mod:`~mjx_hands.mocap.mapping`, converted by :mod:`~mjx_hands.mocap.capture`; the
project's skeleton for export: :mod:`~mjx_hands.mocap.skeleton`), driven by
``python -m mjx_hands.import_mocap``.

Frames, and what the release's arrays hold as verified against the data: see
:mod:`~mjx_hands.mocap.release`. Every position and orientation of a Demonstration is
in the target hand's palm frame.

Every array read is checked for damage, dtype and shape, and every frame used for
plausibility (:data:`POSITION_BOUND`, :data:`JOINT_ANGLE_BOUND`,
:data:`QUAT_NORM_TOLERANCE`); anything wrong raises :class:`MocapError` naming the file.
"""

from __future__ import annotations

from pathlib import Path

from mjx_hands.mocap.demonstration import (
    DEFAULT_FPS,
    JOINT_ANGLE_BOUND,
    POSITION_BOUND,
    QUAT_DROPOUT_NORM,
    QUAT_NORM_TOLERANCE,
    REAL_DATA_PATH,
    SOURCES,
    SYNTHETIC_PATH,
    TASKS,
    Demonstration,
    MocapError,
    build_demonstration,
    check_task,
    fit_rigid,
    matrix_to_quat_wxyz,
    quat_wxyz_to_matrix,
    quat_xyzw_to_matrix,
    rotation_angle,
    to_model_convention,
)
from mjx_hands.mocap.npz import (
    SCHEMA_VERSION,
    demos_from_arrays,
    demos_to_arrays,
    load_synthetic,
    save_npz,
)
from mjx_hands.mocap.release import (
    APPROACH_FAR,
    APPROACH_NEAR,
    CALIBRATION_LEAD_IN,
    CAPTURE_TO_SIM,
    ORIGINAL_CALIBRATION,
    ORIGINAL_PALM_ALIGNMENT,
    RELEASE_JOINT_OFFSET,
    IndexAlignment,
    PalmCalibration,
    Release,
    apply_index_alignment,
    approach_start,
    calibration_samples,
    estimate_index_alignment,
    estimate_palm_calibration,
    fit_palm_calibration,
    load_optitrack,
    read_release,
)


def load_demonstrations(
    task: str,
    source: str = "auto",
    path: str | Path | None = None,
    fps: float = DEFAULT_FPS,
) -> list[Demonstration]:
    """Demonstrations of ``task`` for the environment.

    Args:
      task: one of TASKS.
      source: "optitrack" (the authors' release), "synthetic" (mocap_data/) or "auto":
        the release at ``path`` (or REAL_DATA_PATH) when it holds this task, otherwise the
        project's synthetic files at ``path`` (or SYNTHETIC_PATH).
      path: folder of the chosen source; default per source as above.
      fps: capture rate assumed for the release (synthetic files store their own).
    """
    check_task(task)
    if source not in SOURCES:
        raise MocapError(f"unknown mocap source {source!r}; valid sources: {', '.join(SOURCES)}")
    if path is not None and not Path(path).is_dir():
        raise MocapError(f"mocap folder {path} does not exist")
    if source == "auto":
        real = Path(path) if path is not None else REAL_DATA_PATH
        if (real / f"{task}_interaction_t.npy").is_file():
            source = "optitrack"
        else:
            source, path = "synthetic", (path if path is not None else SYNTHETIC_PATH)
    if source == "optitrack":
        return load_optitrack(task, path, fps=fps)
    return load_synthetic(task, path)


__all__ = [
    "APPROACH_FAR",
    "APPROACH_NEAR",
    "CALIBRATION_LEAD_IN",
    "CAPTURE_TO_SIM",
    "DEFAULT_FPS",
    "JOINT_ANGLE_BOUND",
    "ORIGINAL_CALIBRATION",
    "ORIGINAL_PALM_ALIGNMENT",
    "POSITION_BOUND",
    "QUAT_DROPOUT_NORM",
    "QUAT_NORM_TOLERANCE",
    "REAL_DATA_PATH",
    "RELEASE_JOINT_OFFSET",
    "SCHEMA_VERSION",
    "SOURCES",
    "SYNTHETIC_PATH",
    "TASKS",
    "Demonstration",
    "IndexAlignment",
    "MocapError",
    "PalmCalibration",
    "Release",
    "apply_index_alignment",
    "approach_start",
    "build_demonstration",
    "calibration_samples",
    "check_task",
    "demos_from_arrays",
    "demos_to_arrays",
    "estimate_index_alignment",
    "estimate_palm_calibration",
    "fit_palm_calibration",
    "fit_rigid",
    "load_demonstrations",
    "load_optitrack",
    "load_synthetic",
    "matrix_to_quat_wxyz",
    "quat_wxyz_to_matrix",
    "quat_xyzw_to_matrix",
    "read_release",
    "rotation_angle",
    "save_npz",
    "to_model_convention",
]

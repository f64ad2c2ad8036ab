"""The authors' OptiTrack release: reader, palm calibration, E.T. index alignment,
where each demonstration begins, and :func:`load_optitrack`.

Frames (all right-handed):

* *palm frame* of a hand: origin ``PALM_CENTER`` in ``robot0:palm``, axes of that body
  (+z wrist->fingers, +x thumb side, -y palmar side); see ``hand_kinematics``.
* *target palm frame*: the palm frame of the target hand. Every position and
  orientation of a Demonstration is expressed in it, so the placement of the pair in
  the world does not matter.
* *capture frame*: OptiTrack world, Y up. :data:`CAPTURE_TO_SIM` turns it into a
  simulator world with Z up (only relative quantities leave this module, so this
  choice cancels; it is kept so that intermediate world-frame arrays are Z-up).
* *mocap palm frame*: the OptiTrack rigid body on the back of each hand. It is not the
  Shadow palm frame; :class:`PalmCalibration` maps one to the other (fitted to the data
  by :func:`estimate_palm_calibration`).

What the release's arrays hold, as verified against the data (README.md of the
release differs in two places; see ``mocap_data/README.md``):

* ``<task>_distance_array_palms.npy`` (T,1,1,3): target palm - actor palm (mocap
  origins), capture frame.
* ``<task>_distance_array_palms_1.npy`` (T,1,6,3): target palm, then the 5 *target*
  fingertips (th, ff, mf, rf, lf), each minus the actor palm. The fingertip geometry
  moves rigidly with ``rot_human``'s palm, not with ``rot_robot``'s.
* ``<task>_rot_{human,robot}.npy``: unit quaternions x, y, z, w rotating mocap-body
  coordinates into the capture frame; bodies palm, th, ff, mf, rf, lf.
* ``<task>_joint_angles_*.npy`` have fewer rows than the capture arrays; they are
  aligned to the *end* of the take (row ``i`` is frame ``i + T - T_joints``), which the
  finger-body quaternions confirm (their rotation rates correlate with the joint
  rates at exactly that lag). ``T - T_joints`` is fixed per task
  (:data:`RELEASE_JOINT_OFFSET`) and checked.

Every array read is checked for damage, dtype and shape, and every frame used for
plausibility (:data:`POSITION_BOUND`, :data:`JOINT_ANGLE_BOUND`,
:data:`QUAT_NORM_TOLERANCE`); anything wrong raises :class:`MocapError` naming the file.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np

from mjx_hands import hand_kinematics
from mjx_hands.mocap.demonstration import (
    DEFAULT_FPS,
    QUAT_DROPOUT_NORM,
    REAL_DATA_PATH,
    Demonstration,
    MocapError,
    build_demonstration,
    check_bounds,
    check_dtype,
    check_task,
    fit_rigid,
    quat_xyzw_to_matrix,
    rotation_angle,
    to_model_convention,
    vector_norm,
)
from mjx_hands.shadow_hand import HAND_JOINTS, HAND_POINTS

CAPTURE_TO_SIM = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""Capture (Y up) -> simulator (Z up): +90 deg about x, (x, y, z) -> (x, -z, y). Applied to
vectors as ``CAPTURE_TO_SIM @ v`` and to orientations as ``CAPTURE_TO_SIM @ R``."""

ORIGINAL_PALM_ALIGNMENT = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
"""The authors' (x, y, z) -> (z, y, -x), i.e. orientations rotated -90 deg about y. Their
code applies it to vectors already expressed in the mocap *palm* frame, so it is a
mocap-palm -> Shadow-palm alignment (it keeps Y as Y and cannot make a Y-up world Z-up).
The fitted :class:`PalmCalibration` lies ~20 deg from it."""

RELEASE_JOINT_OFFSET = {"handshake": 1, "handclap": 1, "et": 3}
"""Capture frames before the first joint-angle row of the authors' release, per task: the
joint arrays are aligned to the end of the take and hold ``T - offset`` rows (handshake
9117 of 9118 frames, hand clap 7018 of 7019, E.T. 6263 of 6266). :func:`read_release`
requires exactly this, since a joint array cut short at its end would otherwise shift
every row by the missing frames. Pass ``joint_offset=`` to read another release."""


@dataclasses.dataclass(frozen=True)
class PalmCalibration:
    """Mocap palm rigid body -> Shadow palm frame: ``p_shadow = rotation @ p_mocap + offset``.

    rotation: (3, 3) mocap palm-body axes -> Shadow palm-frame axes.
    offset: (3,) mocap rigid-body origin in the Shadow palm frame, metres.
    rms: RMS fingertip residual of the fit, metres (nan when not fitted).
    finger_rms: (5,) RMS residual per finger (th, ff, mf, rf, lf).
    num_frames: frames used by the fit.
    """

    rotation: np.ndarray
    offset: np.ndarray
    rms: float = float("nan")
    finger_rms: np.ndarray = dataclasses.field(default_factory=lambda: np.full(5, np.nan))
    num_frames: int = 0


ORIGINAL_CALIBRATION = PalmCalibration(ORIGINAL_PALM_ALIGNMENT, np.zeros(3))
"""The authors' fixed alignment with no offset (for comparison only)."""


@dataclasses.dataclass(frozen=True)
class Release:
    """One task's take from the authors' release, converted to the simulator world.

    windows: (N, 3) int [start, contact_begin, contact_end] frame indices.
    palm_vec: (T, 3) target palm - actor palm (mocap origins), sim world, metres.
    target_tips: (T, 5, 3) or None: target fingertips - target palm (mocap origin), sim world.
    target_rot, actor_rot: (T, 3, 3) mocap palm-body rotations, sim world.
    target_joints, actor_joints: (T, 20) raw angles in the authors' convention, aligned to
      frames; rows before ``joint_offset`` are NaN (not recorded).
    joint_offset: first frame with joint angles.
    target_quat_norm, actor_quat_norm: (T,) norms of the palm quaternions as stored (a
      frame's rotation is NaN where the norm is below ``QUAT_DROPOUT_NORM`` or NaN).
    target_points: (T, 6, 3) or None: target palm and fingertips - actor palm, sim world,
      as released (``target_tips`` is derived from it).
    """

    task: str
    root: Path
    windows: np.ndarray
    palm_vec: np.ndarray
    target_tips: np.ndarray | None
    target_rot: np.ndarray
    actor_rot: np.ndarray
    target_joints: np.ndarray
    actor_joints: np.ndarray
    joint_offset: int
    target_quat_norm: np.ndarray
    actor_quat_norm: np.ndarray
    target_points: np.ndarray | None

    @property
    def num_frames(self) -> int:
        return int(self.palm_vec.shape[0])


# ------------------------------------------------------------ the authors' release
def _read_npy(path: Path) -> np.ndarray:
    """The array in the .npy file ``path``; MocapError naming it for any damage."""
    try:
        with open(path, "rb") as fh:
            array = np.load(fh, allow_pickle=False)
            end = fh.tell()
            trailing = isinstance(array, np.ndarray) and fh.read(1) != b""
    except Exception as e:  # damaged bytes: NumPy raises many types (ValueError, EOFError...)
        raise MocapError(f"cannot read mocap file {path}: {type(e).__name__}: {e}") from e
    if not isinstance(array, np.ndarray):
        raise MocapError(f"{path}: not an .npy array (got {type(array).__name__})")
    if trailing:  # e.g. a header that claims fewer rows than were written
        raise MocapError(
            f"{path}: data continues after the {array.shape} array its header describes "
            f"(got {path.stat().st_size} bytes, expected {end})"
        )
    return array


def _load_npy(
    root: Path,
    file: str,
    dims: tuple[int | None, ...] | list,
    required: bool = True,
    kind: str = "float",
):
    """Load ``root/file`` and check its shape against ``dims`` (None: any length) and its
    dtype against ``kind`` ("float" or "int").

    ``dims`` may be a list of alternative shapes. Returns None for a missing optional file.
    """
    path = root / file
    if not path.is_file():
        if not required:
            return None
        raise MocapError(f"missing mocap file {path}")
    array = _read_npy(path)
    options = dims if isinstance(dims, list) else [dims]
    if not any(
        array.ndim == len(shape) and all(s is None or s == a for s, a in zip(shape, array.shape))
        for shape in options
    ):
        expected = " or ".join(
            "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")" for shape in options
        )
        raise MocapError(f"{path}: expected shape {expected}, got {array.shape}")
    check_dtype(str(path), "array", array, kind)
    return array


def _joint_offset(task: str, joint_offset: int | None) -> int:
    """The frames before the first joint row: given, or the authors' release's for ``task``."""
    if joint_offset is None:
        return RELEASE_JOINT_OFFSET[task]
    if isinstance(joint_offset, bool) or not isinstance(joint_offset, (int, np.integer)):
        raise MocapError(f"joint_offset must be an int, got {joint_offset!r}")
    if joint_offset < 0:
        raise MocapError(f"joint_offset must be >= 0, got {joint_offset}")
    return int(joint_offset)


def _palm_rotations(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Palm quaternions x, y, z, w (T, 4), capture frame -> rotations (T, 3, 3), sim world,
    NaN at dropouts, and the stored norms (T,) (checked where frames are used)."""
    norm = vector_norm(q)
    dropout = ~((norm > QUAT_DROPOUT_NORM) & np.isfinite(norm))  # also catches NaN
    unit = np.where(
        dropout[:, None],
        [0.0, 0.0, 0.0, 1.0],
        q / np.where(dropout, 1.0, norm)[:, None],
    )
    r = CAPTURE_TO_SIM @ quat_xyzw_to_matrix(unit)
    r[dropout] = np.nan
    return r, norm


def read_release(
    task: str, root: str | Path | None = None, joint_offset: int | None = None
) -> Release:
    """Read and check one task's arrays of the authors' release.

    Args:
      task: one of TASKS.
      root: folder of the release (default ``REAL_DATA_PATH``).
      joint_offset: capture frames before the first joint-angle row; the joint arrays
        must hold exactly ``T - joint_offset`` rows. Default: the authors' release's
        (``RELEASE_JOINT_OFFSET[task]``).

    Raises MocapError for an unknown task, a missing or damaged file, a wrong shape or
    dtype, inconsistent lengths, no windows, or window indices outside the take. Values
    are checked where they are used (:func:`load_optitrack`, :func:`calibration_samples`).
    """
    check_task(task)
    root = Path(root) if root is not None else REAL_DATA_PATH
    offset = _joint_offset(task, joint_offset)
    windows_file = root / f"{task}_interaction_t.npy"
    windows = _load_npy(root, windows_file.name, (None, 3), kind="int")
    if len(windows) == 0:
        raise MocapError(f"{windows_file}: no demonstrations (got 0 rows, expected at least 1)")
    palms = _load_npy(root, f"{task}_distance_array_palms.npy", (None, 1, 1, 3))[:, 0, 0]
    tips = _load_npy(root, f"{task}_distance_array_palms_1.npy", (None, 1, 6, 3), required=False)
    rot_t = _load_npy(root, f"{task}_rot_human.npy", (None, 24))
    rot_a = _load_npy(root, f"{task}_rot_robot.npy", [(None, 24), (None, 4)])
    joints_t = _load_npy(root, f"{task}_joint_angles_human.npy", (None, len(HAND_JOINTS)))
    joints_a = _load_npy(root, f"{task}_joint_angles_robot.npy", (None, len(HAND_JOINTS)))

    n = len(palms)
    for file, array in [
        (f"{task}_rot_human.npy", rot_t),
        (f"{task}_rot_robot.npy", rot_a),
        (f"{task}_distance_array_palms_1.npy", tips),
    ]:
        if array is not None and len(array) != n:
            raise MocapError(
                f"{root / file}: expected {n} frames (as in {task}_distance_array_palms.npy), "
                f"got {len(array)}"
            )
    # Joint rows are aligned to the end of the take: a known offset, not n - len(joints),
    # so that rows missing at the end cannot shift every other row silently.
    for file, joints in [
        (f"{task}_joint_angles_human.npy", joints_t),
        (f"{task}_joint_angles_robot.npy", joints_a),
    ]:
        if len(joints) != n - offset:
            raise MocapError(
                f"{root / file}: {len(joints)} rows for a take of {n} frames (got {len(joints)}, "
                f"expected {n - offset}: rows are frames {offset}..{n - 1}, joint_offset={offset})"
            )
    for i, (s, c0, c1) in enumerate(windows):
        if not offset <= s <= c0 <= c1 < n:
            raise MocapError(
                f"{windows_file} row {i}: [start, contact_begin, contact_end] = "
                f"[{s}, {c0}, {c1}] must satisfy "
                f"{offset} <= start <= contact_begin <= contact_end < {n}"
            )

    def aligned(j):
        out = np.full((n, len(HAND_JOINTS)), np.nan)
        out[offset:] = j
        return out

    with np.errstate(all="ignore"):  # damaged values become NaN/inf here, caught where used
        target_rot, target_norm = _palm_rotations(rot_t[:, :4])
        actor_rot, actor_norm = _palm_rotations(rot_a[:, :4])
        points = None if tips is None else tips[:, 0].astype(np.float64) @ CAPTURE_TO_SIM.T
        return Release(
            task=task,
            root=root,
            windows=windows.astype(np.int64),
            palm_vec=palms.astype(np.float64) @ CAPTURE_TO_SIM.T,
            target_tips=None if points is None else points[:, 1:] - points[:, :1],
            target_rot=target_rot,
            actor_rot=actor_rot,
            target_joints=aligned(joints_t),
            actor_joints=aligned(joints_a),
            joint_offset=offset,
            target_quat_norm=target_norm,
            actor_quat_norm=actor_norm,
            target_points=points,
        )


def _check_window_finite(release: Release, row: int, s: int, c1: int) -> None:
    """Raise MocapError when frames s..c1 (window ``row``) hold NaN/inf, dropouts or values
    outside the plausibility bounds (POSITION_BOUND, JOINT_ANGLE_BOUND, QUAT_NORM_TOLERANCE)."""
    f = slice(s, c1 + 1)
    frames = np.arange(s, c1 + 1)
    context = f", inside window {row} [{s}, {c1}] of {release.task}_interaction_t.npy"
    palm = vector_norm(release.palm_vec[f])
    checks = [
        ("distance_array_palms", "palm-to-palm vector", "length", palm),
        ("rot_human", "palm quaternion", "norm", release.target_quat_norm[f]),
        ("rot_robot", "palm quaternion", "norm", release.actor_quat_norm[f]),
        ("joint_angles_human", "joint", "angle", release.target_joints[f]),
        ("joint_angles_robot", "joint", "angle", release.actor_joints[f]),
    ]
    for field, name, quantity, values in checks:
        where = str(release.root / f"{release.task}_{field}.npy")
        columns = HAND_JOINTS if quantity == "angle" else None
        check_bounds(where, name, quantity, values, frames, columns, context)


CALIBRATION_LEAD_IN = 200
"""Frames before each window's start that also enter the calibration fit (the approach,
where the target palm turns, makes the rotation well determined)."""


def calibration_samples(
    root: str | Path | None = None,
    tasks: tuple[str, ...] = ("handshake", "handclap"),
    lead_in: int = CALIBRATION_LEAD_IN,
    joint_offsets: dict[str, int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Target fingertips as measured (mocap palm frame) and as modelled (Shadow palm frame).

    Frames: every window of ``tasks`` from ``lead_in`` frames before its start to its
    contact_end, where all inputs are finite (capture dropouts are skipped); the values
    of those frames must be within the plausibility bounds, and each task must have at
    least one such frame (MocapError otherwise). ``joint_offsets``: per task, as
    :func:`read_release`'s ``joint_offset`` (default: the authors' release's).
    Returns:
      measured: (N, 5, 3) fingertip - palm origin in mocap palm-body coordinates, in the
        release's fingertip order; modelled: (N, 5, 3) FK of the target joint angles in
        the Shadow palm frame (th, ff, mf, rf, lf).
    """
    root = Path(root) if root is not None else REAL_DATA_PATH
    joint_offsets = joint_offsets or {}
    measured, modelled = [], []
    for task in tasks:
        rel = read_release(task, root, joint_offsets.get(task))
        if rel.target_tips is None:
            raise MocapError(f"{task}_distance_array_palms_1.npy is needed for the calibration")
        frames = np.unique(
            np.concatenate(
                [np.arange(max(s - lead_in, rel.joint_offset), c1 + 1) for s, _, c1 in rel.windows]
            )
        )
        finite = {
            "distance_array_palms_1": np.isfinite(rel.target_points[frames]).all(axis=(1, 2)),
            "rot_human": np.isfinite(rel.target_rot[frames]).all(axis=(1, 2)),
            "joint_angles_human": np.isfinite(rel.target_joints[frames]).all(axis=1),
        }
        ok = np.logical_and.reduce(list(finite.values()))
        if not ok.any():  # the fit would silently rest on the other tasks alone
            empty = [name for name, f in finite.items() if not f.any()] or list(finite)
            raise MocapError(
                f"{root}: palm calibration has no usable frame of {task} (got 0 of "
                f"{len(frames)} frames finite in "
                + ", ".join(f"{task}_{name}.npy" for name in empty)
                + ", expected at least 1); pass calibration= to skip the fit"
            )
        used, joints = frames[ok], rel.target_joints[frames[ok]]
        files = {name: str(root / f"{task}_{name}.npy") for name in finite}
        context = f", a calibration frame of {task}"
        for name, what, quantity, values, columns in [
            ("distance_array_palms_1", "target point vector", "length",
             vector_norm(rel.target_points[used]), ("palm",) + HAND_POINTS[1:]),
            ("rot_human", "palm quaternion", "norm", rel.target_quat_norm[used], None),
            ("joint_angles_human", "joint", "angle", joints, HAND_JOINTS),
        ]:  # fmt: skip
            check_bounds(files[name], what, quantity, values, used, columns, context)
        local = np.einsum("tji,tkj->tki", rel.target_rot[used], rel.target_tips[used])
        measured.append(local)
        modelled.append(
            hand_kinematics.forward_kinematics(to_model_convention(joints)).points[:, 1:]
        )
    return np.concatenate(measured), np.concatenate(modelled)


def fit_palm_calibration(measured: np.ndarray, modelled: np.ndarray) -> PalmCalibration:
    """One rigid transform taking measured (N, 5, 3) onto modelled (N, 5, 3) fingertips."""
    rotation, offset = fit_rigid(measured.reshape(-1, 3), modelled.reshape(-1, 3))
    residual = np.linalg.norm(measured @ rotation.T + offset - modelled, axis=-1)  # (N, 5)
    return PalmCalibration(
        rotation=rotation,
        offset=offset,
        rms=float(np.sqrt(np.mean(residual**2))),
        finger_rms=np.sqrt(np.mean(residual**2, axis=0)),
        num_frames=len(measured),
    )


def estimate_palm_calibration(
    root: str | Path | None = None,
    tasks: tuple[str, ...] = ("handshake", "handclap"),
    lead_in: int = CALIBRATION_LEAD_IN,
    joint_offsets: dict[str, int] | None = None,
) -> PalmCalibration:
    """Fit the mocap-palm -> Shadow-palm transform to the target hand's fingertips.

    The release measures the target fingertips relative to the target palm
    (``distance_array_palms_1``); expressed in the mocap palm frame they must equal the
    Shadow FK of the target joint angles in the Shadow palm frame, up to one rigid
    transform (Kabsch with translation, pooled over the tasks' windows and lead-ins).
    The same transform is applied to both hands (same marker set-up). E.T. has no
    fingertip array, so it is calibrated by the other tasks. ``joint_offsets`` as in
    :func:`calibration_samples`.
    """
    return fit_palm_calibration(*calibration_samples(root, tasks, lead_in, joint_offsets))


@functools.lru_cache(maxsize=4)
def _cached_calibration(
    root: str, joint_offsets: tuple[tuple[str, int], ...] = ()
) -> PalmCalibration:
    """The default calibration of a release: fitted to whichever fingertip arrays it has.

    joint_offsets: (task, offset) pairs for tasks that differ from the authors' release.
    """
    tasks = tuple(
        t
        for t in ("handshake", "handclap")
        if (Path(root) / f"{t}_distance_array_palms_1.npy").is_file()
    )
    if not tasks:
        raise MocapError(
            f"{root} has no handshake/handclap_distance_array_palms_1.npy to fit the palm "
            "calibration to; pass calibration= explicitly"
        )
    return estimate_palm_calibration(root, tasks, joint_offsets=dict(joint_offsets))


@dataclasses.dataclass(frozen=True)
class IndexAlignment:
    """Fixed correction of the E.T. actor palm pose, in the actor palm frame.

    ``rot' = rot @ rotation``, ``centre' = centre + rot @ offset``: ``rotation`` (3, 3) is the
    smallest rotation (a swing, no twist about the finger) that aims the actor's index at
    the target's index tip, ``offset`` (3,) then moves the palm along the finger so that the
    tips meet, on average over all contact windows.
    swing_deg: angle of ``rotation``. residual: (N,) index tip-to-tip distance at each
    demonstration's contact_begin after the correction, metres.
    """

    rotation: np.ndarray
    offset: np.ndarray
    swing_deg: float
    residual: np.ndarray


def _swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation (3, 3) taking the direction of a (3,) to that of b (3,)."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    v, c = np.cross(a, b), float(a @ b)
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


def estimate_index_alignment(demos: list[Demonstration]) -> IndexAlignment:
    """Fit the E.T. correction: actor index tip onto target index tip during contact.

    Why: E.T.'s actor palm comes from a palm-only rigid body (``et_rot_robot.npy`` is
    (T, 4)) recorded apart from the 6-body set-up the calibration was fitted to, and
    the Shadow index is ~3 cm longer than a human one; uncorrected, the actor's
    Shadow index tip ends 7-8 cm from the target's at contact (consistently ~30 deg off
    to the thumb side in every demonstration), which would teach a touch that misses.
    """
    ff = 1 + HAND_POINTS[1:].index("fftip")
    goal, tip = [], []
    for d in demos:
        f = slice(d.contact_begin, d.contact_end + 1)
        centre, rot = d.actor_points[f, 0], d.actor_palm_rot[f]
        goal.append(np.einsum("tji,tj->ti", rot, d.target_points[f, ff] - centre))
        tip.append(np.einsum("tji,tj->ti", rot, d.actor_points[f, ff] - centre))
    goal_mean, tip_mean = np.concatenate(goal).mean(0), np.concatenate(tip).mean(0)
    rotation = _swing(tip_mean, goal_mean)
    offset = goal_mean - rotation @ tip_mean
    residual = []
    for d in demos:
        c = d.contact_begin
        rot = d.actor_palm_rot[c]
        local = rot.T @ (d.actor_points[c, ff] - d.actor_points[c, 0])
        moved = d.actor_points[c, 0] + rot @ (offset + rotation @ local)
        residual.append(np.linalg.norm(moved - d.target_points[c, ff]))
    swing = float(np.degrees(rotation_angle(np.eye(3), rotation)))
    return IndexAlignment(rotation, offset, swing, np.array(residual))


def apply_index_alignment(demos: list[Demonstration], align: IndexAlignment) -> list[Demonstration]:
    """Demonstrations with the actor palm pose corrected by ``align`` (fingertips by FK)."""
    out = []
    for d in demos:
        rot = d.actor_palm_rot @ align.rotation
        centre = d.actor_points[:, 0] + d.actor_palm_rot @ align.offset
        out.append(
            build_demonstration(
                task=d.task,
                name=d.name,
                source=d.source,
                fps=d.fps,
                actor_joints=d.actor_joints,
                target_joints=d.target_joints,
                actor_palm_pos=centre,
                actor_palm_rot=rot,
                contact_begin=d.contact_begin,
                contact_end=d.contact_end,
                target_palm_rot=d.target_palm_rot,
                target_palm_pos=d.target_palm_pos,
            )
        )
    return out


APPROACH_NEAR = 0.10
"""Metres: a release window whose palms start within this of their closest distance
(over the window) begins after the approach (every hand clap: 0-7 mm; handshakes
>= 138 mm, E.T. >= 63 mm)."""
APPROACH_FAR = 0.20
"""Metres: such a demonstration starts instead at the last earlier frame where the
palms were this much farther apart than at their closest."""


def approach_start(palm_distance: np.ndarray, start: int, contact_end: int, first: int = 0) -> int:
    """Where a demonstration begins: the release's ``start``, or earlier when the hands
    are already together there.

    The hand clap's release windows begin at the clap itself (closest palms, speed ~0,
    within -17..+3 frames) and end as the hands part: the approach, what the paper's
    clap result is about, lies before them. The rule is on the palm-to-palm distance
    alone: if at ``start`` the palms are within ``APPROACH_NEAR`` of their closest over
    ``[start, contact_end]``, the demonstration starts at the last frame before ``start``
    at which they were ``APPROACH_FAR`` farther apart (not before ``first``).

    Args:
      palm_distance: (T,) palm-to-palm distance of the take, metres.
      start, contact_end: the release's window (frame indices).
      first: the earliest frame allowed (e.g. the previous demonstration's end).
    Returns:
      the start frame (``start`` when no frame since ``first`` is that far out).
    """
    closest = float(np.min(palm_distance[start : contact_end + 1]))
    if palm_distance[start] - closest >= APPROACH_NEAR:
        return start
    far = np.flatnonzero(palm_distance[first:start] > closest + APPROACH_FAR)
    return first + int(far[-1]) if far.size else start  # no approach recorded: as released


def load_optitrack(
    task: str,
    root: str | Path | None = None,
    fps: float = DEFAULT_FPS,
    calibration: PalmCalibration | None = None,
    lead_in: int = 0,
    align_et_index: bool = True,
    approach: bool = True,
    joint_offset: int | None = None,
) -> list[Demonstration]:
    """The authors' demonstrations of one task, one per row of ``<task>_interaction_t.npy``.

    Args:
      task: one of TASKS.
      root: folder of the release (default ``REAL_DATA_PATH``).
      fps: capture rate to assume, Hz (not stored in the release; see DEFAULT_FPS).
      calibration: mocap-palm -> Shadow-palm transform for both hands; default: fitted to
        the handshake and hand-clap takes of ``root`` (:func:`estimate_palm_calibration`).
      lead_in: extra frames before each window's start (the authors' environments also
        started episodes before it); contact indices shift accordingly.
      approach: begin windows that start with the hands already together (the hand
        clap's) at the approach instead (:func:`approach_start`).
      align_et_index: for "et", correct the actor palm pose so that the index tips meet
        during contact (:func:`estimate_index_alignment`).
      joint_offset: capture frames before the first joint-angle row of ``task`` (see
        :func:`read_release`); default: the authors' release's, ``RELEASE_JOINT_OFFSET``.
    Returns:
      Demonstrations named ``<task>/optitrack/<row>``; actor fingertips by FK of the actor
      joints from the actor palm pose, target fingertips by FK of the target joints.
    Raises:
      MocapError naming the file for damaged, inconsistent or implausible data in any
      frame used (see :func:`read_release` and the ``*_BOUND`` constants).
    """
    check_task(task)
    root = Path(root) if root is not None else REAL_DATA_PATH
    release = read_release(task, root, joint_offset)
    offsets = () if joint_offset is None else ((task, joint_offset),)
    cal = calibration
    if cal is None:
        cal = _cached_calibration(str(root.resolve()), offsets)
    c, o = cal.rotation, cal.offset
    demos = []
    distance = vector_norm(release.palm_vec)
    previous_end = release.joint_offset
    for row, (s0, c0, c1) in enumerate(release.windows):
        s = max(int(s0) - lead_in, release.joint_offset)
        if approach:
            earlier = approach_start(distance, int(s0), int(c1), previous_end)
            span = slice(earlier, int(s0))  # capture dropouts there: keep the release's start
            recorded = [
                getattr(release, name)[span]
                for name in (
                    "palm_vec",
                    "actor_joints",
                    "target_joints",
                    "actor_rot",
                    "target_rot",
                )
            ]
            if all(np.isfinite(x).all() for x in recorded):
                s = min(s, earlier)
        previous_end = max(previous_end, int(c1) + 1)
        _check_window_finite(release, row, s, int(c1))
        f = slice(s, c1 + 1)
        # Shadow palm axes in the world: R_mocap @ C^T.  Relative actor pose (target frame):
        #   rot = C Rt^T Ra C^T,  centre = C Rt^T (actor - target origin) + o - rot @ o.
        r_t = release.target_rot[f] @ c.T
        r_a = release.actor_rot[f] @ c.T
        rot = np.swapaxes(r_t, -1, -2) @ r_a
        centre = np.einsum("tji,tj->ti", r_t, -release.palm_vec[f]) + o - rot @ o
        demos.append(
            build_demonstration(
                task=task,
                name=f"{task}/optitrack/{row:02d}",
                source="optitrack",
                fps=fps,
                actor_joints=to_model_convention(release.actor_joints[f]),
                target_joints=to_model_convention(release.target_joints[f]),
                actor_palm_pos=centre,
                actor_palm_rot=rot,
                contact_begin=c0 - s,
                contact_end=c1 - s,
                target_palm_rot=r_t,  # the palm's own turning; its position is not recorded
            )
        )
    if task == "et" and align_et_index:
        demos = apply_index_alignment(demos, estimate_index_alignment(demos))
    return demos

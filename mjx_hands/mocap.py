"""Human demonstrations of the three hand interactions, in the target hand's palm frame.

Two sources produce the same :class:`Demonstration` (host-side NumPy):

* ``"optitrack"`` -- the authors' released OptiTrack arrays (``../shared/mocap/
  drl_handshake`` beside the repository; never copied into it), read by
  :func:`load_optitrack`;
* ``"synthetic"`` -- the project's own demonstrations in ``mocap_data/`` (written by
  ``python -m mjx_hands.synthetic_demos``), read by :func:`load_synthetic`.

:func:`load_demonstrations` is what the environment calls.

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

from mjx_hands import hand_kinematics, package_data, tasks
from mjx_hands.shadow_hand import HAND_JOINTS, HAND_POINTS

TASKS = tasks.TASKS
"""The three interactions (names used in files and configs)."""

SOURCES = ("auto", "optitrack", "synthetic")

DEFAULT_FPS = 120.0
"""Capture rate assumed for the OptiTrack release, Hz (not stored in it). Evidence:
the authors' environments stepped 4-6 frames per 0.04 s (100-150 Hz); peak palm-to-palm
approach speeds of 0.0044-0.0056 m/frame (handshake) are human (0.3-2 m/s) for roughly
70-360 Hz; the handshake hold (palms within 3 cm of their contact distance) lasts a
median 260 frames, which matches the 1.96 +- 0.46 s contact phase measured for
human handshakes (Frontiers in Robotics and AI 9:758519, 2022) for ~105-170 Hz. 120 Hz,
OptiTrack's standard rate, is inside all three; at it the approach peaks at 0.5-0.7 m/s
(handshake) and 0.7-1.2 m/s (hand clap). Pass ``fps=`` to assume another rate."""

REPO_ROOT = package_data.REPO_ROOT
REAL_DATA_PATH = REPO_ROOT.parent / "shared" / "mocap" / "drl_handshake"
"""The authors' release beside the repository (read-only, never copied in)."""
SYNTHETIC_PATH = package_data.data_dir("mocap_data")
"""The project's own demonstrations."""

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

SCHEMA_VERSION = 1
"""Version of the ``mocap_data/<task>.npz`` layout (see mocap_data/README.md)."""


POSITION_BOUND = 3.0
"""Metres: the longest plausible palm-to-palm or palm-to-fingertip vector (two people's
hands cannot be farther apart). Checked on every frame a demonstration or the palm
calibration uses, and on every frame of an npz file. Measured: release 1.38 m at most
over all frames (0.93 m inside windows and calibration lead-ins), synthetic files 0.66 m."""
JOINT_ANGLE_BOUND = float(np.pi)
"""Radians: the largest plausible |joint angle| (before clipping into the model's ranges,
which would hide a damaged value). Measured: release 3.03 rad at most over all frames
(handshake target LFJ1; 2.71 rad inside windows and lead-ins), synthetic files 1.46 rad."""
QUAT_NORM_TOLERANCE = 0.1
"""Largest |norm - 1| of a palm quaternion that is used (release: 1e-6, synthetic float32
files: 6e-8). Outside the frames used, a norm below ``QUAT_DROPOUT_NORM`` (or NaN) is a
capture dropout and becomes a NaN rotation, as before."""
QUAT_DROPOUT_NORM = 0.5
"""Release quaternions with a smaller norm (zeros) or a NaN are capture dropouts."""


class MocapError(ValueError):
    """Demonstration data that is missing, malformed or inconsistent."""


# --------------------------------------------------------------------------- checks
_DTYPES = {  # kind: (numpy dtype kinds accepted, what the message says is expected)
    "float": ("f", "a real floating-point dtype (float16/32/64)"),
    "int": ("iu", "an integer dtype"),
    "str": ("U", "a unicode str dtype"),
}
_BOUNDS = {  # quantity: (lower, upper, unit)
    "length": (0.0, POSITION_BOUND, "m"),
    "angle": (-JOINT_ANGLE_BOUND, JOINT_ANGLE_BOUND, "rad"),
    "norm": (1.0 - QUAT_NORM_TOLERANCE, 1.0 + QUAT_NORM_TOLERANCE, ""),
}


def _check_dtype(where: str, name: str, array: np.ndarray, kind: str) -> None:
    """MocapError unless ``array`` has a dtype of ``kind`` ("float", "int" or "str").

    Why: NumPy turns bool, integer, datetime, string and complex arrays into floats
    without complaint (complex silently loses its imaginary part), so a damaged file
    would become wrong angles instead of an error.
    """
    kinds, expected = _DTYPES[kind]
    if array.dtype.kind not in kinds:
        raise MocapError(
            f"{where}: {name} has the wrong dtype (got {array.dtype}, expected {expected})"
        )


def _vector_norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norms over the last axis; hypot does not overflow for huge (damaged) values."""
    return np.hypot.reduce(np.asarray(v, np.float64), axis=-1)


def _first_outside(values: np.ndarray, lower: float, upper: float) -> tuple[int, int] | None:
    """(row, column) of the first entry of ``values`` (R, K) outside [lower, upper], NaN too."""
    with np.errstate(invalid="ignore"):
        bad = ~((values >= lower) & (values <= upper))
    if not bad.any():
        return None
    row, col = np.unravel_index(int(np.argmax(bad)), bad.shape)
    return int(row), int(col)


def _check_bounds(
    where: str,
    name: str,
    quantity: str,
    values: np.ndarray,
    rows: np.ndarray | None = None,
    columns: tuple[str, ...] | None = None,
    context: str = "",
    at: str = "frame",
) -> None:
    """MocapError at the first of ``values`` (R, ...) outside the bounds of ``quantity``.

    rows: the frame/row number of each of the R rows (default 0..R-1); columns: names of
    the entries of a row (e.g. joint names) for the message.
    """
    lower, upper, unit = _BOUNDS[quantity]
    values = np.asarray(values, np.float64).reshape(len(values), -1)
    hit = _first_outside(values, lower, upper)
    if hit is None:
        return
    r, c = hit
    row = r if rows is None else int(rows[r])
    item = f" ({columns[c]})" if columns else ""
    unit = f" {unit}" if unit else ""
    raise MocapError(
        f"{where}: {name} {quantity} out of bounds at {at} {row}{item}{context} "
        f"(got {values[r, c]:.6g}{unit}, expected {lower:.6g}..{upper:.6g}{unit})"
    )


def _check_shape(where: str, name: str, array: np.ndarray, shape: tuple[int, ...]) -> None:
    if array.shape != shape:
        raise MocapError(f"{where}: {name} must have shape {shape}, got {array.shape}")


# --------------------------------------------------------------------------- types
@dataclasses.dataclass(frozen=True)
class Demonstration:
    """One demonstration, frames 0..T-1 of its window, in the target palm frame.

    task: "handshake" | "handclap" | "et".
    name: e.g. "handshake/optitrack/03", "et/synthetic/02".
    source: "optitrack" | "synthetic".
    fps: capture rate, Hz.
    actor_joints: (T, 20) radians, ``HAND_JOINTS`` order, gymnasium-robotics convention
      (THJ0 in [-1.571, 0]), clipped into the model's joint ranges.
    target_joints: (T, 20) same for the target hand.
    actor_points: (T, 6, 3) actor palm centre + 5 fingertips (``HAND_POINTS``), metres.
    actor_palm_rot: (T, 3, 3) actor palm-body axes (columns).
    target_points: (T, 6, 3) target palm centre (zeros) + fingertips, by FK of target_joints.
    target_frames: (T, 6, 3, 3) target palm (identity) and distal bodies th..lf.
    contact_begin: frame index where contact starts.
    contact_end: frame index where contact ends (<= T-1).
    """

    task: str
    name: str
    source: str
    fps: float
    actor_joints: np.ndarray
    target_joints: np.ndarray
    actor_points: np.ndarray
    actor_palm_rot: np.ndarray
    target_points: np.ndarray
    target_frames: np.ndarray
    contact_begin: int
    contact_end: int

    @property
    def num_frames(self) -> int:
        return int(self.actor_joints.shape[0])

    def validate(self) -> Demonstration:
        """Check shapes, finiteness and indices; raise MocapError naming the field."""
        if self.task not in TASKS:
            raise MocapError(f"{self.name}: task {self.task!r} is not one of {TASKS}")
        if self.source not in ("optitrack", "synthetic"):
            raise MocapError(f"{self.name}: source {self.source!r} is not optitrack/synthetic")
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise MocapError(f"{self.name}: fps must be a positive number, got {self.fps}")
        t = self.num_frames
        n = len(HAND_POINTS)
        shapes = {
            "actor_joints": (t, len(HAND_JOINTS)),
            "target_joints": (t, len(HAND_JOINTS)),
            "actor_points": (t, n, 3),
            "actor_palm_rot": (t, 3, 3),
            "target_points": (t, n, 3),
            "target_frames": (t, n, 3, 3),
        }
        for field, shape in shapes.items():
            value = getattr(self, field)
            if not isinstance(value, np.ndarray) or value.shape != shape:
                got = getattr(value, "shape", type(value).__name__)
                raise MocapError(f"{self.name}: {field} must have shape {shape}, got {got}")
            if not np.all(np.isfinite(value)):
                raise MocapError(f"{self.name}: {field} has non-finite values")
        if t < 2:
            raise MocapError(f"{self.name}: needs at least 2 frames, got {t}")
        if not 0 <= self.contact_begin <= self.contact_end <= t - 1:
            raise MocapError(
                f"{self.name}: contact_begin/contact_end must satisfy 0 <= begin <= end <= "
                f"{t - 1}, got {self.contact_begin}, {self.contact_end}"
            )
        return self


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


# ------------------------------------------------------------------------ geometry
def quat_xyzw_to_matrix(q: np.ndarray) -> np.ndarray:
    """Unit quaternions stored x, y, z, w (..., 4) -> rotation matrices (..., 3, 3)."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def matrix_to_quat_wxyz(r: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> unit quaternions w, x, y, z (..., 4), w >= 0."""
    r = np.asarray(r, dtype=np.float64)
    flat = r.reshape(-1, 3, 3)
    out = np.empty((len(flat), 4))
    for i, m in enumerate(flat):
        # Largest-diagonal branch keeps the division well conditioned.
        tr = np.trace(m)
        if tr > 0:
            s = 2.0 * np.sqrt(1.0 + tr)
            q = [
                0.25 * s,
                (m[2, 1] - m[1, 2]) / s,
                (m[0, 2] - m[2, 0]) / s,
                (m[1, 0] - m[0, 1]) / s,
            ]
        else:
            k = int(np.argmax(np.diag(m)))
            i1, i2 = (k + 1) % 3, (k + 2) % 3
            s = 2.0 * np.sqrt(1.0 + m[k, k] - m[i1, i1] - m[i2, i2])
            q = np.empty(4)
            q[0] = (m[i2, i1] - m[i1, i2]) / s
            q[1 + k] = 0.25 * s
            q[1 + i1] = (m[i1, k] + m[k, i1]) / s
            q[1 + i2] = (m[i2, k] + m[k, i2]) / s
        q = np.asarray(q) / np.linalg.norm(q)
        out[i] = q if q[0] >= 0 else -q
    return out.reshape(r.shape[:-2] + (4,))


def quat_wxyz_to_matrix(q: np.ndarray) -> np.ndarray:
    """Unit quaternions w, x, y, z (..., 4) -> rotation matrices (..., 3, 3)."""
    return quat_xyzw_to_matrix(np.roll(q, -1, axis=-1))


def fit_rigid(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotation + translation with ``target ~ rotation @ source + offset``.

    Args:
      source, target: (N, 3) corresponding points.
    Returns:
      rotation (3, 3) (proper, det +1), offset (3,).
    """
    ms, mt = source.mean(0), target.mean(0)
    u, _, vt = np.linalg.svd((source - ms).T @ (target - mt))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rotation, mt - rotation @ ms


def rotation_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (radians) of the rotation between orientations a and b (..., 3, 3)."""
    c = (np.trace(np.swapaxes(a, -1, -2) @ b, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def to_model_convention(angles: np.ndarray) -> np.ndarray:
    """Authors' joint angles (..., 20) -> gymnasium-robotics convention, clipped to range.

    THJ0 changes sign: the authors' model had it in [0, 1.571], ours in [-1.571, 0].
    """
    out = np.array(angles, dtype=np.float64, copy=True)
    out[..., HAND_JOINTS.index("THJ0")] *= -1.0
    return hand_kinematics.clip_to_range(out)


# ---------------------------------------------------------------- demonstrations
def build_demonstration(
    *,
    task: str,
    name: str,
    source: str,
    fps: float,
    actor_joints: np.ndarray,
    target_joints: np.ndarray,
    actor_palm_pos: np.ndarray,
    actor_palm_rot: np.ndarray,
    contact_begin: int,
    contact_end: int,
) -> Demonstration:
    """A Demonstration from joint angles and the actor palm pose; fingertips by FK.

    Args:
      actor_joints, target_joints: (T, 20) in the model convention (clipped here).
      actor_palm_pos: (T, 3) actor palm centre in the target palm frame.
      actor_palm_rot: (T, 3, 3) actor palm axes in the target palm frame.
    """
    actor_joints = hand_kinematics.clip_to_range(np.asarray(actor_joints, np.float64))
    target_joints = hand_kinematics.clip_to_range(np.asarray(target_joints, np.float64))
    actor_palm_pos = np.asarray(actor_palm_pos, np.float64)
    actor_palm_rot = np.asarray(actor_palm_rot, np.float64)
    actor = hand_kinematics.forward_kinematics(actor_joints)
    target = hand_kinematics.forward_kinematics(target_joints)
    actor_points = actor_palm_pos[:, None] + np.einsum("tij,tkj->tki", actor_palm_rot, actor.points)
    return Demonstration(
        task=task,
        name=name,
        source=source,
        fps=float(fps),
        actor_joints=actor_joints,
        target_joints=target_joints,
        actor_points=actor_points,
        actor_palm_rot=actor_palm_rot,
        target_points=target.points,
        target_frames=target.frames,
        contact_begin=int(contact_begin),
        contact_end=int(contact_end),
    ).validate()


def _check_task(task: str) -> None:
    if task not in TASKS:
        raise MocapError(f"unknown task {task!r}; valid tasks: {', '.join(TASKS)}")


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
    _check_dtype(str(path), "array", array, kind)
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
    norm = _vector_norm(q)
    dropout = ~((norm > QUAT_DROPOUT_NORM) & np.isfinite(norm))  # also catches NaN
    unit = np.where(
        dropout[:, None], [0.0, 0.0, 0.0, 1.0], q / np.where(dropout, 1.0, norm)[:, None]
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
    _check_task(task)
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
    palm = _vector_norm(release.palm_vec[f])
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
        _check_bounds(where, name, quantity, values, frames, columns, context)


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
             _vector_norm(rel.target_points[used]), ("palm",) + HAND_POINTS[1:]),
            ("rot_human", "palm quaternion", "norm", rel.target_quat_norm[used], None),
            ("joint_angles_human", "joint", "angle", joints, HAND_JOINTS),
        ]:  # fmt: skip
            _check_bounds(files[name], what, quantity, values, used, columns, context)
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
    _check_task(task)
    root = Path(root) if root is not None else REAL_DATA_PATH
    release = read_release(task, root, joint_offset)
    offsets = () if joint_offset is None else ((task, joint_offset),)
    cal = calibration
    if cal is None:
        cal = _cached_calibration(str(root.resolve()), offsets)
    c, o = cal.rotation, cal.offset
    demos = []
    distance = _vector_norm(release.palm_vec)
    previous_end = release.joint_offset
    for row, (s0, c0, c1) in enumerate(release.windows):
        s = max(int(s0) - lead_in, release.joint_offset)
        if approach:
            earlier = approach_start(distance, int(s0), int(c1), previous_end)
            span = slice(earlier, int(s0))  # capture dropouts there: keep the release's start
            recorded = [
                getattr(release, name)[span]
                for name in ("palm_vec", "actor_joints", "target_joints", "actor_rot", "target_rot")
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
            )
        )
    if task == "et" and align_et_index:
        demos = apply_index_alignment(demos, estimate_index_alignment(demos))
    return demos


# ------------------------------------------------------------ the project's own files
_NPZ_PER_DEMO = ("names", "fps", "num_frames", "contact_begin", "contact_end")
_NPZ_PER_FRAME = {
    "actor_joints": (len(HAND_JOINTS),),
    "target_joints": (len(HAND_JOINTS),),
    "actor_palm_pos": (3,),
    "actor_palm_quat": (4,),
}
_NPZ_DTYPES = {
    "schema_version": "int",
    "task": "str",
    "names": "str",
    "fps": "float",
    "num_frames": "int",
    "contact_begin": "int",
    "contact_end": "int",
    **{key: "float" for key in _NPZ_PER_FRAME},
}
"""Every array of the npz layout and the dtype kind it must have (see :func:`_check_dtype`)."""


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
    return {
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
    ]:
        values = arrays[key] if quantity == "angle" else _vector_norm(arrays[key])
        _check_bounds(where, key, quantity, values, columns=columns, at="row")


def demos_from_arrays(arrays, task: str, source: str, where: str = "arrays") -> list[Demonstration]:
    """Inverse of demos_to_arrays (fingertips recomputed by FK). ``where`` names the file.

    Checks every array's presence, dtype and shape, the values of every frame against the
    plausibility bounds, and that there is at least one demonstration; unknown arrays are
    an error too (nothing in a file is silently ignored). Raises MocapError naming
    ``where`` and the array.
    """
    missing = [key for key in _NPZ_DTYPES if key not in arrays]
    if missing:
        raise MocapError(f"{where}: missing array {missing[0]!r}")
    unknown = sorted(set(arrays) - set(_NPZ_DTYPES))
    if unknown:
        raise MocapError(
            f"{where}: unknown array {unknown[0]!r} (got {len(arrays)} arrays, expected "
            f"only {', '.join(_NPZ_DTYPES)} of schema {SCHEMA_VERSION})"
        )
    a = {key: np.asarray(arrays[key]) for key in _NPZ_DTYPES}
    for key, kind in _NPZ_DTYPES.items():
        _check_dtype(where, key, a[key], kind)
    _check_shape(where, "schema_version", a["schema_version"], ())
    if int(a["schema_version"]) != SCHEMA_VERSION:
        raise MocapError(
            f"{where}: schema_version {int(a['schema_version'])}, expected {SCHEMA_VERSION}"
        )
    _check_shape(where, "task", a["task"], ())
    if str(a["task"]) != task:
        raise MocapError(f"{where}: holds task {str(a['task'])!r}, expected {task!r}")
    if a["num_frames"].ndim != 1:
        raise MocapError(f"{where}: num_frames must have shape (N,), got {a['num_frames'].shape}")
    n = len(a["num_frames"])
    for key in _NPZ_PER_DEMO:
        _check_shape(where, key, a[key], (n,))
    if n == 0:
        raise MocapError(f"{where}: no demonstrations (got 0, expected at least 1)")
    lengths = [int(x) for x in a["num_frames"]]  # Python ints: no overflow in the sum
    if min(lengths) < 2:
        i = int(np.argmin(lengths))
        raise MocapError(
            f"{where}: num_frames of demonstration {i} too small (got {lengths[i]}, expected >= 2)"
        )
    total = sum(lengths)
    for key, tail in _NPZ_PER_FRAME.items():
        _check_shape(where, key, a[key], (total, *tail))
    _npz_frame_checks(where, a)
    bounds = np.concatenate([[0], np.cumsum(lengths)])
    demos = []
    for i in range(n):
        f = slice(int(bounds[i]), int(bounds[i + 1]))
        quat = np.asarray(a["actor_palm_quat"][f], np.float64)
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
    _check_task(task)
    file = Path(path if path is not None else SYNTHETIC_PATH) / f"{task}.npz"
    if not file.is_file():
        raise MocapError(
            f"missing synthetic demonstrations {file}; run `python -m mjx_hands.synthetic_demos`"
        )
    return demos_from_arrays(_read_npz(file), task, "synthetic", where=str(file))


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
    _check_task(task)
    if source not in SOURCES:
        raise MocapError(f"unknown mocap source {source!r}; valid sources: {', '.join(SOURCES)}")
    if source == "auto":
        real = Path(path) if path is not None else REAL_DATA_PATH
        if (real / f"{task}_interaction_t.npy").is_file():
            source = "optitrack"
        else:
            source, path = "synthetic", (path if path is not None else SYNTHETIC_PATH)
    if source == "optitrack":
        return load_optitrack(task, path, fps=fps)
    return load_synthetic(task, path)

"""The demonstration type shared by every source, its checks and geometry helpers.

A :class:`Demonstration` holds one human demonstration in the target hand's palm frame
(host-side NumPy); :mod:`mjx_hands.mocap.release` reads the authors' recordings into it
and :mod:`mjx_hands.mocap.npz` the project's own files. The checks here (dtypes,
plausibility bounds, shapes) are what both loaders apply, so that anything wrong raises
:class:`MocapError` naming the file.
"""

from __future__ import annotations

import dataclasses

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


ROTATION_TOLERANCE = 1e-4
"""Largest |R^T R - I| entry of a stored rotation matrix (float32 round trips: ~1e-7)."""


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


def check_dtype(where: str, name: str, array: np.ndarray, kind: str) -> None:
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


def vector_norm(v: np.ndarray) -> np.ndarray:
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


def check_bounds(
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


def check_shape(where: str, name: str, array: np.ndarray, shape: tuple[int, ...]) -> None:
    if array.shape != shape:
        raise MocapError(f"{where}: {name} must have shape {shape}, got {array.shape}")


# --------------------------------------------------------------------------- types
@dataclasses.dataclass(frozen=True)
class Demonstration:
    """One demonstration, frames 0..T-1 of its window, in the target palm frame.

    task: a registered task (``tasks.TASKS``).
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
    target_palm_rot: (T, 3, 3) the target palm's own turning: its axes at each frame in
      its frame of the window's first frame (so ``[0]`` is the identity). A source that
      recorded no orientation (the project's designed demonstrations, schema-1 files)
      holds the identity: a target that does not turn.
    target_palm_pos: (T, 3) or None: the target palm centre in the same frame (``[0]``
      zero), where the source recorded it (imported takes); None where only the
      palm-to-palm vector was recorded (the authors' release), for which
      :mod:`mjx_hands.partner` models the target's share of the approach.
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
    target_palm_rot: np.ndarray | None = None
    target_palm_pos: np.ndarray | None = None

    def __post_init__(self):
        if self.target_palm_rot is None:  # frozen dataclass: set the documented default
            turn = np.broadcast_to(np.eye(3), (self.num_frames, 3, 3)).copy()
            object.__setattr__(self, "target_palm_rot", turn)

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
            "target_palm_rot": (t, 3, 3),
        }
        if self.target_palm_pos is not None:
            shapes["target_palm_pos"] = (t, 3)
        for field, shape in shapes.items():
            value = getattr(self, field)
            if not isinstance(value, np.ndarray) or value.shape != shape:
                got = getattr(value, "shape", type(value).__name__)
                raise MocapError(f"{self.name}: {field} must have shape {shape}, got {got}")
            if not np.all(np.isfinite(value)):
                raise MocapError(f"{self.name}: {field} has non-finite values")
        if t < 2:
            raise MocapError(f"{self.name}: needs at least 2 frames, got {t}")
        rot = self.target_palm_rot
        orthonormal = np.abs(np.swapaxes(rot, -1, -2) @ rot - np.eye(3)).max()
        if orthonormal > ROTATION_TOLERANCE or np.linalg.det(rot).min() < 0:
            raise MocapError(
                f"{self.name}: target_palm_rot must hold rotation matrices (got an error of "
                f"{orthonormal:.3g} from orthonormal, expected <= {ROTATION_TOLERANCE})"
            )
        if not 0 <= self.contact_begin <= self.contact_end <= t - 1:
            raise MocapError(
                f"{self.name}: contact_begin/contact_end must satisfy 0 <= begin <= end <= "
                f"{t - 1}, got {self.contact_begin}, {self.contact_end}"
            )
        return self


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
    target_palm_rot: np.ndarray | None = None,
    target_palm_pos: np.ndarray | None = None,
) -> Demonstration:
    """A Demonstration from joint angles and the actor palm pose; fingertips by FK.

    Args:
      actor_joints, target_joints: (T, 20) in the model convention (clipped here).
      actor_palm_pos: (T, 3) actor palm centre in the target palm frame.
      actor_palm_rot: (T, 3, 3) actor palm axes in the target palm frame.
      target_palm_rot: (T, 3, 3) the target palm's axes in any fixed frame (re-expressed
        here in its frame of frame 0); None: a target that does not turn.
      target_palm_pos: (T, 3) the target palm centre in that same fixed frame; None:
        not recorded.
    """
    if target_palm_rot is not None:
        target_palm_rot = np.asarray(target_palm_rot, np.float64)
        first = target_palm_rot[0].T
        if target_palm_pos is not None:
            target_palm_pos = np.asarray(target_palm_pos, np.float64)
            target_palm_pos = (target_palm_pos - target_palm_pos[0]) @ first.T
        target_palm_rot = first @ target_palm_rot
    elif target_palm_pos is not None:
        raise MocapError(f"{name}: target_palm_pos needs the target_palm_rot of its frame")
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
        target_palm_rot=target_palm_rot,
        target_palm_pos=target_palm_pos,
    ).validate()


def check_task(task: str) -> None:
    if task not in TASKS:
        raise MocapError(f"unknown task {task!r}; valid tasks: {', '.join(TASKS)}")

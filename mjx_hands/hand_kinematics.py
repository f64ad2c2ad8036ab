"""Forward kinematics of one Shadow hand in its own palm frame (host-side NumPy).

The *palm frame* of a hand has its origin at ``PALM_CENTER`` inside the
``robot0:palm`` body and the axes of that body: +z runs from the wrist to the
fingers, +x points to the thumb side, -y is the palmar side (fingers flex
towards -y). Everything here is independent of the arm and of the wrist joints.

Used at load time only (mocap fingertip reconstruction, synthetic demos); the
model is native MuJoCo built once from the gymnasium-robotics MJCF.
"""

from __future__ import annotations

import dataclasses
import functools
import os

import mujoco
import numpy as np

from mjx_hands.shadow_hand import (
    ALL_HAND_JOINTS,
    FINGERS,
    FINGERTIPS,
    HAND_JOINTS,
    PALM_CENTER,
    asset_dir,
    full_hand_angles,
    hand_name,
)

DISTAL_BODIES = tuple(f"{f}distal" for f in FINGERS)
"""Distal body of each finger, in ``FINGERS`` order (rows 1..5 of ``frames``)."""


@dataclasses.dataclass(frozen=True)
class HandPose:
    """Forward kinematics of a sequence of hand postures, in the palm frame.

    points: (T, 6, 3) palm centre (zeros) + fingertip sites, ``HAND_POINTS`` order, metres.
    frames: (T, 6, 3, 3) rotation of the palm body (identity) and of the 5 distal bodies
      (``DISTAL_BODIES``); columns are the body axes in palm-frame coordinates.
    """

    points: np.ndarray
    frames: np.ndarray


@dataclasses.dataclass(frozen=True)
class _Hand:
    model: mujoco.MjModel
    qpos_adr: np.ndarray  # (24,) qpos address of each ALL_HAND_JOINTS joint
    lower: np.ndarray  # (24,) joint range, ALL_HAND_JOINTS order
    upper: np.ndarray
    palm: int  # body id of robot0:palm
    distal: np.ndarray  # (5,) body ids, DISTAL_BODIES order
    tips: np.ndarray  # (5,) site ids, FINGERTIPS order


@functools.lru_cache(maxsize=1)
def _hand() -> _Hand:
    # reach.xml is the smallest scene of the package that holds exactly one hand.
    model = mujoco.MjSpec.from_file(os.path.join(asset_dir(), "reach.xml")).compile()

    def jid(n):
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, hand_name(n))

    joints = np.array([jid(n) for n in ALL_HAND_JOINTS])
    return _Hand(
        model=model,
        qpos_adr=model.jnt_qposadr[joints].copy(),
        lower=model.jnt_range[joints, 0].copy(),
        upper=model.jnt_range[joints, 1].copy(),
        palm=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, hand_name("palm")),
        distal=np.array(
            [
                mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, hand_name(b))
                for b in DISTAL_BODIES
            ]
        ),
        tips=np.array(
            [
                mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, hand_name("S_" + t))
                for t in FINGERTIPS
            ]
        ),
    )


def hand_model() -> mujoco.MjModel:
    """The lone stock hand (compiled once): geometry and kinematics, no dynamics use."""
    return _hand().model


def joint_range() -> tuple[np.ndarray, np.ndarray]:
    """Range of the 20 actuated joints in the gymnasium-robotics model.

    Returns:
      (lower, upper): each (20,), ``HAND_JOINTS`` order, radians.
    """
    h = _hand()
    idx = [ALL_HAND_JOINTS.index(n) for n in HAND_JOINTS]
    return h.lower[idx].copy(), h.upper[idx].copy()


def clip_to_range(angles: np.ndarray) -> np.ndarray:
    """Clip actuated angles (..., 20) into the model's joint ranges."""
    lower, upper = joint_range()
    return np.clip(angles, lower, upper)


def _check_angles(angles: np.ndarray) -> np.ndarray:
    angles = np.atleast_2d(np.asarray(angles, dtype=np.float64))
    if angles.shape[-1] != len(HAND_JOINTS) or angles.ndim != 2:
        raise ValueError(f"angles must be (T, {len(HAND_JOINTS)}), got {angles.shape}")
    return angles


def _palm_frames(angles: np.ndarray):
    """Run FK per posture; yield ``(data, origin, r_palm)`` of the palm frame in the model.

    angles: (T, 20), clipped into the model's ranges (coupled distal joints too).
    """
    h = _hand()
    q = np.clip(full_hand_angles(angles), h.lower, h.upper)  # (T, 24)
    data = mujoco.MjData(h.model)
    center = np.asarray(PALM_CENTER)
    for qt in q:
        data.qpos[h.qpos_adr] = qt
        mujoco.mj_kinematics(h.model, data)
        r_palm = data.xmat[h.palm].reshape(3, 3)
        yield data, data.xpos[h.palm] + r_palm @ center, r_palm


def forward_kinematics(angles: np.ndarray) -> HandPose:
    """Palm-frame fingertips and distal-body orientations of hand postures.

    Args:
      angles: (T, 20) or (20,) actuated angles, ``HAND_JOINTS`` order, radians, in the
        gymnasium-robotics convention (THJ0 in [-1.571, 0]). Angles outside the model's
        ranges are clipped, as is each coupled distal joint (J0 = 1.14 * J1 can exceed
        its range).
    Returns:
      HandPose with points (T, 6, 3) and frames (T, 6, 3, 3) (no T axis for (20,) input).
    """
    single = np.ndim(angles) == 1
    angles = _check_angles(angles)
    h = _hand()
    points = np.zeros((len(angles), 6, 3))
    frames = np.empty((len(angles), 6, 3, 3))
    for t, (data, origin, r_palm) in enumerate(_palm_frames(angles)):
        points[t, 1:] = (data.site_xpos[h.tips] - origin) @ r_palm
        frames[t, 0] = np.eye(3)
        frames[t, 1:] = r_palm.T @ data.xmat[h.distal].reshape(-1, 3, 3)
    if single:
        return HandPose(points=points[0], frames=frames[0])
    return HandPose(points=points, frames=frames)


def link_poses(angles: np.ndarray, links: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Palm-frame poses of hand bodies (names without prefix) for postures (T, 20).

    Returns:
      positions (T, len(links), 3) and quaternions (T, len(links), 4), ``w, x, y, z``.
    """
    angles = _check_angles(angles)
    model = _hand().model
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, hand_name(n)) for n in links]
    pos = np.empty((len(angles), len(ids), 3))
    quat = np.empty((len(angles), len(ids), 4))
    for t, (data, origin, r_palm) in enumerate(_palm_frames(angles)):
        pos[t] = (data.xpos[ids] - origin) @ r_palm
        for k, mat in enumerate(r_palm.T @ data.xmat[ids].reshape(-1, 3, 3)):
            mujoco.mju_mat2Quat(quat[t, k], mat.reshape(9))
    return pos, quat

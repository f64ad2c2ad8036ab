"""Building blocks of hand-designed demonstrations (host-side NumPy).

A task module (``mjx_hands.tasks.<name>``) describes its synthetic demonstrations with
these: postures from named joint angles, the contact pose of the actor palm in the
target palm frame (a function of the two postures), and a few distances taken from the
Shadow model's geometry. ``mjx_hands.synthetic_demos`` turns such a design into
minimum-jerk approaches. Frames: the palm frame of ``hand_kinematics`` (+z wrist to
fingers, +x thumb side, -y palmar side).
"""

from __future__ import annotations

import numpy as np

from mjx_hands import hand_kinematics
from mjx_hands.shadow_hand import HAND_JOINTS, HAND_POINTS

PALM_GAP = 2 * 0.0111
"""Palm-centre separation of two palms in contact: twice the half-thickness of the
Shadow palm's collision box ``C_palm0``, metres."""
PAD_GAP = 0.00705 + 0.005
"""Fingertip-site distance when one index tip presses on the other's pad: the distal
capsule radius plus the 5 mm from the tip site to the capsule's end."""
UP = np.array([0.0, 1.0, 0.0])
"""The palm frame's y axis (the back of the hand)."""


def posture(**angles: float) -> np.ndarray:
    """A (20,) hand posture in HAND_JOINTS order from named angles (others 0)."""
    unknown = set(angles) - set(HAND_JOINTS)
    if unknown:
        raise ValueError(f"unknown joints {sorted(unknown)}; expected names of {HAND_JOINTS}")
    return np.array([angles.get(n, 0.0) for n in HAND_JOINTS])


RELAXED = posture(THJ3=0.3, THJ1=0.1, FFJ2=0.1, FFJ1=0.1, MFJ2=0.12, MFJ1=0.12,
                  RFJ2=0.15, RFJ1=0.15, LFJ2=0.18, LFJ1=0.18)  # fmt: skip
"""Open, relaxed hand at the start of an approach."""


def columns(x, y, z) -> np.ndarray:
    """The rotation (3, 3) whose columns are the axes ``x``, ``y``, ``z`` (3,) each."""
    return np.stack([x, y, z], axis=-1).astype(np.float64)


def rodrigues(w: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of rotation vector w (3,)."""
    angle = np.linalg.norm(w)
    if angle < 1e-12:
        return np.eye(3)
    k = w / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


def minimum_jerk(tau: np.ndarray) -> np.ndarray:
    """Minimum-jerk profile s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5, tau clipped to [0, 1]."""
    t = np.clip(tau, 0.0, 1.0)
    return t**3 * (10 - 15 * t + 6 * t**2)


def point(joints: np.ndarray, name: str) -> np.ndarray:
    """Palm-frame position (3,) of a HAND_POINTS entry for a (20,) posture."""
    return hand_kinematics.forward_kinematics(joints).points[HAND_POINTS.index(name)]


def link_position(joints: np.ndarray, link: str) -> np.ndarray:
    """Palm-frame position (3,) of a hand body's origin (e.g. 'ffmiddle') for a (20,)
    posture."""
    positions, _ = hand_kinematics.link_poses(np.asarray(joints)[None], (link,))
    return positions[0, 0]

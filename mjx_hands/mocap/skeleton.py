"""The project's own hand skeleton: the nodes, offsets and channels that ``export`` writes
(BVH and Motive CSV alike) and the mapping that reads them back.

Nodes sit at the Shadow hand's bodies at the zero posture; every node rotates in the
Euler order :data:`EULER` with flexion about x and abduction (or the thumb's rotation)
about y, so the middle (z) angle is always 0 and a rotation decomposes exactly.
"""

from __future__ import annotations

import functools

import numpy as np

from mjx_hands.mocap.mapping import FORMATS, Bone, HandMapping, JointSource, Mapping
from mjx_hands.shadow_hand import HAND_JOINTS

ROOT = "RightForearm"
PALM = "RightHand"
FOREARM_OFFSET = np.array([0.0, 0.0, 0.08])
"""Where the palm node sits on the forearm, metres (its z runs to the fingers)."""
EULER = "XZY"
"""Euler order (intrinsic) of every node: flexion, an unused middle angle, abduction."""
SKELETON = (
    # node, parent, the hand body at its origin (None: the palm centre), (x joint, y joint)
    ("RightHand", None, None, ("WRJ0", "WRJ1")),
    ("RightHandThumb1", "RightHand", "thproximal", ("THJ3", "THJ4")),
    ("RightHandThumb2", "RightHandThumb1", "thmiddle", ("THJ1", "THJ2")),
    ("RightHandThumb3", "RightHandThumb2", "thdistal", ("THJ0", None)),
    ("RightHandIndex1", "RightHand", "ffproximal", ("FFJ2", "FFJ3")),
    ("RightHandIndex2", "RightHandIndex1", "ffmiddle", ("FFJ1", None)),
    ("RightHandIndex3", "RightHandIndex2", "ffdistal", ("FFJ1", None)),
    ("RightHandMiddle1", "RightHand", "mfproximal", ("MFJ2", "MFJ3")),
    ("RightHandMiddle2", "RightHandMiddle1", "mfmiddle", ("MFJ1", None)),
    ("RightHandMiddle3", "RightHandMiddle2", "mfdistal", ("MFJ1", None)),
    ("RightHandRing1", "RightHand", "rfproximal", ("RFJ2", "RFJ3")),
    ("RightHandRing2", "RightHandRing1", "rfmiddle", ("RFJ1", None)),
    ("RightHandRing3", "RightHandRing2", "rfdistal", ("RFJ1", None)),
    ("RightHandPinky0", "RightHand", "lfmetacarpal", ("LFJ4", None)),
    ("RightHandPinky1", "RightHandPinky0", "lfproximal", ("LFJ2", "LFJ3")),
    ("RightHandPinky2", "RightHandPinky1", "lfmiddle", ("LFJ1", None)),
    ("RightHandPinky3", "RightHandPinky2", "lfdistal", ("LFJ1", None)),
)
"""The nodes below the forearm. A finger's third node repeats its second one's flexion
(the coupled distal joint), for the look of it; the mapping reads the second."""
PARENT = {node: parent or ROOT for node, parent, _, _ in SKELETON}
TIPS = ("RightHandThumb3", "RightHandIndex3", "RightHandMiddle3", "RightHandRing3",
        "RightHandPinky3")  # fmt: skip
TIP_OFFSET = np.array([0.0, 0.0, 0.026])
"""End site of every finger: the distal phalanx's length along its z, metres."""
FILES = {"actor": "actor.bvh", "target": "target.bvh"}
"""BVH: the skeleton file of each hand in a take folder."""
MOTIVE_SKELETONS = {"actor": "Actor", "target": "Target"}
"""Motive: the skeleton asset of each hand; its bones are named ``Asset:Node``."""


def euler_matrices(angles: np.ndarray, order: str) -> np.ndarray:
    """(T, 3, 3) intrinsic rotations R = R_a1 R_a2 R_a3 of ``angles`` (T, 3) radians about
    the axes of ``order`` (e.g. "XZY")."""
    out = np.broadcast_to(np.eye(3), (len(angles), 3, 3))
    for k, axis in enumerate(order.upper()):
        c, s = np.cos(angles[:, k]), np.sin(angles[:, k])
        i = "XYZ".index(axis)
        j, l = (i + 1) % 3, (i + 2) % 3
        m = np.zeros((len(angles), 3, 3))
        m[:, i, i] = 1.0
        m[:, j, j], m[:, j, l], m[:, l, j], m[:, l, l] = c, -s, s, c
        out = out @ m
    return out


def euler_angles(rot: np.ndarray, order: str) -> np.ndarray:
    """Intrinsic Euler angles (T, 3) in ``order`` of rotations (T, 3, 3): pybvh's
    decomposition (middle angle within +-90 deg)."""
    from pybvh import rotations

    return rotations.rotmat_to_euler(rot, order.upper())


def euler_by_axis(angles: np.ndarray, order: str) -> np.ndarray:
    """Euler angles (T, 3) in ``order`` (e.g. "XZY") as (T, 3) about x, y, z."""
    out = np.empty_like(angles)
    for k, axis in enumerate(order):
        out[:, "XYZ".index(axis)] = angles[:, k]
    return out


@functools.lru_cache(maxsize=1)
def rest_offsets() -> dict[str, np.ndarray]:
    """Each node's offset from its parent at the zero posture, metres."""
    from mjx_hands import hand_kinematics

    bodies = tuple(body for _, _, body, _ in SKELETON if body is not None)
    positions, _ = hand_kinematics.link_poses(np.zeros((1, 20)), bodies)
    at = {None: np.zeros(3)} | dict(zip(bodies, positions[0]))
    body_of = {node: body for node, _, body, _ in SKELETON}
    return {
        node: at[body] - at[body_of[parent]] if parent else FOREARM_OFFSET
        for node, parent, body, _ in SKELETON
    }


def local_angles(joints: np.ndarray) -> dict[str, np.ndarray]:
    """Each node's Euler angles (T, 3) in :data:`EULER` order for postures (T, 20)."""
    column = {name: k for k, name in enumerate(HAND_JOINTS)}
    zeros = np.zeros(len(joints))
    out = {}
    for node, _, _, (x_joint, y_joint) in SKELETON:
        x = joints[:, column[x_joint]] if x_joint else zeros
        y = joints[:, column[y_joint]] if y_joint else zeros
        out[node] = np.stack([x, zeros, y], -1)
    return out


def forearm_pose(
    joints: np.ndarray, palm_pos: np.ndarray, palm_rot: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The root's pose (T, 3) metres, (T, 3, 3) that puts the palm node at ``palm_pos``,
    ``palm_rot`` given the wrist angles of ``joints`` (T, 20)."""
    wrist = euler_matrices(local_angles(joints)[PALM], EULER)
    rot = palm_rot @ np.swapaxes(wrist, -1, -2)
    return palm_pos - np.einsum("tij,j->ti", rot, FOREARM_OFFSET), rot


def world_poses(
    joints: np.ndarray, palm_pos: np.ndarray, palm_rot: np.ndarray
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every node's world position (T, 3) metres and rotation (T, 3, 3), root included."""
    offsets, angles = rest_offsets(), local_angles(joints)
    poses = {ROOT: forearm_pose(joints, palm_pos, palm_rot)}
    for node, _, _, _ in SKELETON:
        pos, rot = poses[PARENT[node]]
        poses[node] = (
            pos + np.einsum("tij,j->ti", rot, offsets[node]),
            rot @ euler_matrices(angles[node], EULER),
        )
    return poses


def mapping(fmt: str, windows: dict[str, tuple[int, int]], fps: float | None = None) -> Mapping:
    """The mapping that reads this skeleton back from ``fmt`` ("bvh" or "motive")."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown format {fmt!r}; expected one of {FORMATS}")

    def hand(which: str) -> HandMapping:
        prefix = f"{MOTIVE_SKELETONS[which]}:" if fmt == "motive" else ""
        joints: dict[str, JointSource] = {}
        for node, _, _, pair in SKELETON:
            for joint, axis in zip(pair, "xy"):
                if joint is not None:
                    joints.setdefault(joint, JointSource(prefix + node, axis))
        bones = {}
        if fmt == "motive":
            bones = {prefix + n: Bone(prefix + PARENT[n], EULER) for n, *_ in SKELETON}
        return HandMapping(
            prefix + PALM,
            np.eye(3),
            np.zeros(3),
            {j: joints[j] for j in HAND_JOINTS},
            file=FILES[which] if fmt == "bvh" else None,
            bones=bones,
        )

    unit = "cm" if fmt == "bvh" else None
    return Mapping(fmt, hand("actor"), hand("target"), unit, fps, windows=dict(windows))

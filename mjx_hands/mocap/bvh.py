"""BVH takes: a folder with one skeleton file per hand (the actor's and the target's,
named by the mapping), read with ``pybvh``; :func:`write_take` writes a demonstration
with the project's skeleton (``mocap.skeleton``) so that it can leave the project and
come back.

The palm node's world pose comes from the hierarchy (offsets and Euler channels, BVH's
intrinsic order); joint angles are the mapped nodes' channels (see ``mapping``).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from mjx_hands.mocap import skeleton
from mjx_hands.mocap.capture import HandTrack, Take, mapped_joints, palm_track
from mjx_hands.mocap.demonstration import Demonstration, MocapError
from mjx_hands.mocap.mapping import LENGTH_UNITS, HandMapping, Mapping

CM = 100.0
"""Centimetres per metre: the project writes BVH lengths in centimetres, as is usual."""


# ------------------------------------------------------------------------------ reading
def _read(path: Path):
    import pybvh

    if not path.is_file():
        raise MocapError(f"BVH file {path} does not exist")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return pybvh.read_bvh_file(path, world_up="+y", warn_on_world_up_disagreement=False)
    except (ValueError, IndexError, KeyError, TypeError, UnicodeDecodeError) as error:
        raise MocapError(f"{path}: not a readable BVH file ({error})") from None


def _hand(path: Path, hand: HandMapping, metres_per_unit: float) -> tuple[HandTrack, float]:
    """One hand's track from its skeleton file, and the file's frame rate."""
    bvh = _read(path)
    if bvh.frame_count < 2:
        raise MocapError(f"{path}: needs at least 2 frames, got {bvh.frame_count}")
    if not (np.all(np.isfinite(bvh.joint_angles)) and np.all(np.isfinite(bvh.root_pos))):
        raise MocapError(f"{path}: motion has non-finite values")
    if not bvh.frame_time > 0:
        raise MocapError(f"{path}: Frame Time must be positive, got {bvh.frame_time}")
    nodes = {n.name: n for n in bvh.nodes if not n.is_end_site()}
    if hand.palm not in nodes:
        raise MocapError(
            f"{path}: no joint {hand.palm!r} (the mapping's palm); it has {sorted(nodes)}"
        )
    orders = {name: "".join(node.rot_channels).upper() for name, node in nodes.items()}
    angles = {name: bvh.joint_angles[:, bvh.joint_index[name]] for name in nodes}
    chain = []
    node = nodes[hand.palm]
    while node is not None:
        chain.append(node)
        node = node.parent
    rot = np.broadcast_to(np.eye(3), (bvh.frame_count, 3, 3))
    pos = np.zeros((bvh.frame_count, 3))
    for node in reversed(chain):  # root first
        pos = pos + np.einsum("tij,j->ti", rot, np.asarray(node.offset, np.float64))
        if node.is_root():
            pos = pos + bvh.root_pos
        rot = rot @ skeleton.euler_matrices(angles[node.name], orders[node.name])
    palm_pos, palm_rot = palm_track(rot, pos, hand, metres_per_unit)
    angle_of = {name: skeleton.euler_by_axis(a, orders[name]) for name, a in angles.items()}
    joints = mapped_joints(str(path), hand, angle_of, bvh.frame_count)
    return HandTrack(palm_pos, palm_rot, joints), 1.0 / bvh.frame_time


def read_take(folder: str | Path, mapping: Mapping) -> Take:
    """The take in ``folder`` (the mapping's actor and target files); MocapError naming
    the file for anything unreadable, unmapped or inconsistent."""
    folder = Path(folder)
    if not folder.is_dir():
        raise MocapError(
            f"BVH take {folder} is not a folder (of {mapping.actor.file} and {mapping.target.file})"
        )
    metres = LENGTH_UNITS[mapping.length_unit or "cm"]
    actor, fps = _hand(folder / mapping.actor.file, mapping.actor, metres)
    target, target_fps = _hand(folder / mapping.target.file, mapping.target, metres)
    if abs(fps - target_fps) > 1e-6 * fps or len(actor.joints) != len(target.joints):
        raise MocapError(
            f"{folder}: the hands' files disagree: {len(actor.joints)} frames at {fps:g} Hz "
            f"against {len(target.joints)} at {target_fps:g} Hz"
        )
    return Take(folder.name, fps, actor, target)


# ------------------------------------------------------------------------------ writing
def _hand_bvh(joints: np.ndarray, palm_pos: np.ndarray, palm_rot: np.ndarray, fps: float):
    """The project's skeleton moving one hand: joints (T, 20) radians, palm pose (T, 3)
    metres and (T, 3, 3) in the file's world; lengths in centimetres."""
    import pybvh
    from pybvh.bvhnode import BvhEndSite, BvhJoint, BvhRoot

    offsets, local = skeleton.rest_offsets(), skeleton.local_angles(joints)
    forearm_pos, forearm_rot = skeleton.forearm_pose(joints, palm_pos, palm_rot)
    order = list(skeleton.EULER)
    root = BvhRoot(skeleton.ROOT, [0.0, 0.0, 0.0], ["X", "Y", "Z"], order)
    nodes, made = [root], {skeleton.ROOT: root}
    for node, *_ in skeleton.SKELETON:
        parent = made[skeleton.PARENT[node]]
        joint = BvhJoint(node, CM * offsets[node], order, [], parent)
        parent.children.append(joint)
        nodes.append(joint)
        made[node] = joint
        if node in skeleton.TIPS:
            end = BvhEndSite(f"{node}_end", CM * skeleton.TIP_OFFSET, joint)
            joint.children.append(end)
            nodes.append(end)
    angles = [skeleton.euler_angles(forearm_rot, skeleton.EULER)]
    angles += [local[n] for n, *_ in skeleton.SKELETON]
    return pybvh.Bvh(
        nodes=nodes,
        root_pos=CM * forearm_pos,
        joint_angles=np.stack(angles, 1),
        frame_time=1.0 / fps,
        world_up="+y",
    )


def write_take(demo: Demonstration, folder: str | Path) -> Path:
    """``demo`` as a BVH take of the project's skeleton in ``folder`` (created): the target
    palm at the origin, the actor where the demonstration has it. Returns the folder."""
    import pybvh

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    frames = demo.num_frames
    target = _hand_bvh(demo.target_joints, np.zeros((frames, 3)),
                       np.broadcast_to(np.eye(3), (frames, 3, 3)), demo.fps)  # fmt: skip
    actor = _hand_bvh(demo.actor_joints, demo.actor_points[:, 0], demo.actor_palm_rot, demo.fps)
    pybvh.write_bvh_file(actor, folder / skeleton.FILES["actor"])
    pybvh.write_bvh_file(target, folder / skeleton.FILES["target"])
    return folder

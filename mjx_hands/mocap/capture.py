"""A lab's take of two hands, as read from BVH or Motive CSV, and its conversion into a
:class:`Demonstration` (the step every importer shares).

A :class:`Take` holds both hands in the capture's world frame, already mapped onto the
project's hands (palm axes and centre, the 20 ``HAND_JOINTS``, metres). :func:`to_demonstration`
expresses the actor in the target's palm frame, resamples to the requested rate, finds
the contact window and validates as the other loaders do.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mjx_hands.mocap.demonstration import (
    Demonstration,
    MocapError,
    build_demonstration,
    check_bounds,
    matrix_to_quat_wxyz,
    quat_wxyz_to_matrix,
    vector_norm,
)
from mjx_hands.mocap.mapping import HandMapping, JointSource, Mapping
from mjx_hands.shadow_hand import HAND_JOINTS


@dataclasses.dataclass(frozen=True)
class HandTrack:
    """One hand of a take in the capture's world frame.

    palm_pos: (T, 3) palm centre, metres. palm_rot: (T, 3, 3) palm axes (columns: the
    project palm's x, y, z). joints: (T, 20) radians, ``HAND_JOINTS`` order.
    """

    palm_pos: np.ndarray
    palm_rot: np.ndarray
    joints: np.ndarray


@dataclasses.dataclass(frozen=True)
class Take:
    """Both hands of one recorded interaction at ``fps`` Hz."""

    name: str
    fps: float
    actor: HandTrack
    target: HandTrack

    @property
    def num_frames(self) -> int:
        return int(self.actor.joints.shape[0])


def palm_track(
    world_rot: np.ndarray, world_pos: np.ndarray, hand: HandMapping, metres_per_unit: float
) -> tuple[np.ndarray, np.ndarray]:
    """The project palm's pose from the capture's palm node pose.

    Args:
      world_rot: (T, 3, 3) the node's axes in the world; world_pos: (T, 3) its origin, file
        units.
    Returns:
      positions (T, 3) metres and rotations (T, 3, 3) of the project's palm.
    """
    rot = world_rot @ hand.palm_axes.T
    pos = world_pos + np.einsum("tij,j->ti", world_rot, hand.palm_centre)
    return pos * metres_per_unit, rot


def mapped_joints(
    where: str, hand: HandMapping, angle_of: dict[str, np.ndarray], frames: int
) -> np.ndarray:
    """(T, 20) joint angles from per-node Euler angles ``angle_of[node]`` (T, 3) in x, y, z
    order (radians), by the hand's joint sources."""
    out = np.empty((frames, len(HAND_JOINTS)))
    for k, joint in enumerate(HAND_JOINTS):
        source: JointSource = hand.joints[joint]
        if source.node is None:
            out[:, k] = source.offset
            continue
        if source.node not in angle_of:
            raise MocapError(
                f"{where}: joint {joint} reads {source.node!r}, which the take does not have "
                f"(it has {sorted(angle_of)})"
            )
        angles = angle_of[source.node][:, "xyz".index(source.axis)]
        out[:, k] = source.sign * angles + source.offset
    return out


def _resample(take: Take, fps: float) -> tuple[Take, np.ndarray]:
    """The take at ``fps`` (linear in positions and angles, normalised-linear in
    quaternions, which is slerp to within 1e-4 rad at capture rates) and the capture frame
    (float) of every new frame."""
    duration = (take.num_frames - 1) / take.fps
    count = int(np.floor(duration * fps + 1e-9)) + 1
    at = np.arange(count) * take.fps / fps
    base = np.arange(take.num_frames)

    def lerp(x: np.ndarray) -> np.ndarray:
        flat = x.reshape(len(x), -1)
        return np.stack([np.interp(at, base, c) for c in flat.T], -1).reshape(
            (count,) + x.shape[1:]
        )

    def track(h: HandTrack) -> HandTrack:
        q = matrix_to_quat_wxyz(h.palm_rot)
        for i in range(1, len(q)):  # each in the hemisphere of the previous one
            if q[i] @ q[i - 1] < 0:
                q[i] = -q[i]
        q = lerp(q)
        q /= np.linalg.norm(q, axis=-1, keepdims=True)
        return HandTrack(lerp(h.palm_pos), quat_wxyz_to_matrix(q), lerp(h.joints))

    return Take(take.name, fps, track(take.actor), track(take.target)), at


def contact_window(take: Take, margin: float) -> tuple[int, int]:
    """From the first frame within ``margin`` metres of the palms' closest approach to the
    last frame."""
    distance = vector_norm(take.actor.palm_pos - take.target.palm_pos)
    return int(np.argmax(distance <= distance.min() + margin)), take.num_frames - 1


def to_demonstration(
    take: Take, task: str, mapping: Mapping, source: str = "synthetic"
) -> Demonstration:
    """The take as a Demonstration of ``task``: actor in the target's palm frame, at the
    mapping's rate, with the mapping's contact window; MocapError naming the take for
    implausible values."""
    where = f"take {take.name}"
    for hand in ("actor", "target"):
        track: HandTrack = getattr(take, hand)
        check_bounds(where, f"{hand} joints", "angle", track.joints, columns=HAND_JOINTS)
        if not np.all(np.isfinite(track.palm_pos)) or not np.all(np.isfinite(track.palm_rot)):
            raise MocapError(f"{where}: {hand} palm has non-finite values")
    capture_frames = take.num_frames
    window = mapping.windows.get(take.name)
    if window is not None and window[1] > capture_frames - 1:
        raise MocapError(
            f"{where}: contact window {list(window)} ends after the last frame {capture_frames - 1}"
        )
    if mapping.fps is not None and abs(mapping.fps - take.fps) > 1e-9:
        take, at = _resample(take, mapping.fps)
        if window is not None:
            window = tuple(int(np.searchsorted(at, w - 1e-9)) for w in window)
            window = (window[0], min(window[1], take.num_frames - 1))
    if window is None:
        window = contact_window(take, mapping.contact_margin)
    target_rot_t = np.swapaxes(take.target.palm_rot, -1, -2)
    actor_pos = np.einsum("tij,tj->ti", target_rot_t, take.actor.palm_pos - take.target.palm_pos)
    check_bounds(where, "actor palm position", "length", vector_norm(actor_pos)[:, None])
    return build_demonstration(
        task=task,
        name=f"{task}/{take.name}",
        source=source,
        fps=take.fps,
        actor_joints=take.actor.joints,
        target_joints=take.target.joints,
        actor_palm_pos=actor_pos,
        actor_palm_rot=target_rot_t @ take.actor.palm_rot,
        contact_begin=window[0],
        contact_end=window[1],
        target_palm_rot=take.target.palm_rot,
        target_palm_pos=take.target.palm_pos,
    )

"""The recorded partner: the requesting hand replays its own recorded approach.

The paper trains against a static target hand. Here the target hand can instead do
what the human did in the demonstration the episode follows: its palm travels and turns
along its recorded path and its fingers move through their recorded angles, closing at
contact, so the hand arrives and reacts as a person did instead of waiting frozen
(``EnvConfig.partner = "recorded"``).

Everything is expressed relative to the demonstration's closest approach ``t_min``:
the environment places the target hand's pose at ``t_min`` where it places the static
target (the task's nominal pose, the episode's box offset and tilt), and the recorded
path moves it from there. The tables are host-side NumPy, built once per environment.

Where a source recorded only where the two palms are relative to each other (the
authors' release: the palm-to-palm vector and each palm's absolute orientation, not the
palms' absolute positions), the target's path is modelled: it covers ``share`` of every
change of the palm-to-palm vector (both hands close in, a human handshake's partners
roughly symmetrically: ``DEFAULT_SHARE``), while the actor covers the rest. Its
orientation is recorded in all sources that turn (release, imported takes).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from mjx_hands import reward_params
from mjx_hands.mocap import Demonstration

DEFAULT_SHARE = 0.5
"""Share of the palms' closing that the target's palm covers where its position was not
recorded: both people move their hands towards each other (0: the target's palm only
turns in place; 1: the actor's palm stays still and the target comes all the way)."""


def approach_path(
    demo: Demonstration, share: float = DEFAULT_SHARE
) -> tuple[np.ndarray, np.ndarray]:
    """The target palm's pose at every frame, in its own frame at frame 0.

    Recorded where the demonstration has ``target_palm_pos``; else its centre moves by
    ``-share`` times the change of the palm-to-palm vector (actor palm minus target
    palm, in frame-0 axes: ``target_palm_rot[t] @ actor palm centre in the target frame``).

    Returns:
      position (T, 3) metres (``[0]`` zero), rotation (T, 3, 3) (``[0]`` identity).
    """
    rot = np.asarray(demo.target_palm_rot, np.float64)
    if demo.target_palm_pos is not None:
        return np.asarray(demo.target_palm_pos, np.float64), rot
    if not 0.0 <= share <= 1.0:
        raise ValueError(f"share {share!r} must be in [0, 1] (the target's part of the approach)")
    between = np.einsum("tij,tj->ti", rot, np.asarray(demo.actor_points, np.float64)[:, 0])
    return -share * (between - between[0]), rot


@dataclasses.dataclass(frozen=True)
class PartnerTables:
    """The recorded partner of every demonstration at every control step from the
    window's start (frame ``k * fps * dt``; past the window's end: its last frame).

    palm_pos: (n_demos, L, 3) the target palm centre relative to its pose at ``t_min``,
      in its frame at ``t_min`` (zero at ``t_min``'s step when ``t_min`` falls on one).
    palm_rot: (n_demos, L, 3, 3) its axes in that frame.
    joints: (n_demos, L, 20) the target hand's joint angles (``HAND_JOINTS``).
    """

    palm_pos: np.ndarray
    palm_rot: np.ndarray
    joints: np.ndarray

    @property
    def length(self) -> int:
        return int(self.joints.shape[1])


def window_steps(demo: Demonstration, dt: float) -> int:
    """Control steps from the window's first frame to its last, inclusive."""
    return (
        reward_params.step_of_frame(demo.num_frames - 1, reward_params.frames_per_step(demo, dt))
        + 1
    )


def partner_tables(
    demos: Sequence[Demonstration],
    t_min_frames: Sequence[int],
    dt: float,
    share: float = DEFAULT_SHARE,
    length: int | None = None,
) -> PartnerTables:
    """The recorded partner of ``demos`` sampled at the control rate.

    Args:
      demos: the task's demonstrations.
      t_min_frames: each one's closest-approach frame (``RewardParams.t_min_frame``).
      dt: control period, seconds.
      share: the target's part of the approach where its position was not recorded.
      length: rows L (default: the longest window in control steps).
    """
    length = max(window_steps(d, dt) for d in demos) if length is None else int(length)
    pos, rot, joints = [], [], []
    for demo, t_min in zip(demos, t_min_frames, strict=True):
        frames = np.minimum(
            np.arange(length) * reward_params.frames_per_step(demo, dt), demo.num_frames - 1
        )
        path_pos, path_rot = approach_path(demo, share)
        at_min = path_rot[int(t_min)].T  # frame-0 axes -> the frame at t_min
        relative_pos = (path_pos - path_pos[int(t_min)]) @ at_min.T
        relative_rot = at_min @ path_rot
        pos.append(reward_params.resample(relative_pos, frames))
        rot.append(reward_params.nearest_rotation(reward_params.resample(relative_rot, frames)))
        joints.append(reward_params.resample(np.asarray(demo.target_joints, np.float64), frames))
    return PartnerTables(np.stack(pos), np.stack(rot), np.stack(joints))

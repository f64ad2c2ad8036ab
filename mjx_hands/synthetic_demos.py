"""The project's own demonstrations: minimum-jerk approaches to hand-designed contacts.

So that a fresh clone trains without the authors' recordings, this generates, for each
task, ``NUM_DEMOS`` demonstrations in the :class:`mocap.Demonstration` schema and
writes them to ``mocap_data/<task>.npz``::

    python -m mjx_hands.synthetic_demos            # regenerate mocap_data/
    python -m mjx_hands.synthetic_demos --out DIR  # elsewhere

Model (all in the target palm frame, see ``mocap``):

* Contact pose of the actor palm, designed from the Shadow model's geometry
  (:func:`contact_pose`): handshake -- palms facing, a palm thickness apart, thumb webs
  interlocked, hands crossed 45 deg in the palm plane; hand clap -- palms flat
  together, fingers antiparallel and aligned, each hand's fingertips on the other's
  upper palm; E.T. -- index pointing into the target's index pad, tips touching,
  other fingers curled.
* Approach: the palm moves on a straight minimum-jerk path (Flash & Hogan 1985) from a
  start 0.30-0.45 m away (backed off along the actor's forearm and out of the target's
  way) while its orientation turns along the geodesic from a perturbed start.
* Fingers: minimum-jerk blend from a relaxed open hand to the task posture; the
  handshake closes further ("squeeze") during contact.
* Target: a static per-task posture.
* Variability per demonstration (seeded): contact offsets of 1-2 cm and a few degrees,
  approach distance, duration and direction, closure amounts, hold time, target
  posture.

No number here comes from the recordings; ``tests/test_mocap.py`` checks the designed
contacts against the real data's mean contact pose.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mjx_hands import hand_kinematics, mocap
from mjx_hands.shadow_hand import HAND_JOINTS, HAND_POINTS, PALM_CENTER

FPS = 120.0
"""Sampling rate of the synthetic demonstrations, Hz (the rate assumed for the release)."""
NUM_DEMOS = 8
SEED = 20190520  # ICRA 2019's opening day; any fixed value works.

PALM_GAP = 2 * 0.0111
"""Palm-centre separation of two palms in contact: twice the half-thickness of the
Shadow palm's collision box ``C_palm0``, metres."""
PAD_GAP = 0.00705 + 0.005
"""Fingertip-site distance when one index tip presses on the other's pad: the distal
capsule radius plus the 5 mm from the tip site to the capsule's end."""


def posture(**angles: float) -> np.ndarray:
    """A (20,) hand posture in HAND_JOINTS order from named angles (others 0)."""
    unknown = set(angles) - set(HAND_JOINTS)
    if unknown:
        raise ValueError(f"unknown joints {sorted(unknown)}")
    return np.array([angles.get(n, 0.0) for n in HAND_JOINTS])


RELAXED = posture(THJ3=0.3, THJ1=0.1, FFJ2=0.1, FFJ1=0.1, MFJ2=0.12, MFJ1=0.12,
                  RFJ2=0.15, RFJ1=0.15, LFJ2=0.18, LFJ1=0.18)  # fmt: skip
"""Open, relaxed hand at the start of an approach."""

ACTOR_POSTURE = {
    # Fingers wrap round the partner's hand, the little finger most; thumb over its back.
    "handshake": posture(WRJ1=-0.2, THJ3=0.8, THJ1=0.4, THJ0=-0.1, FFJ2=0.35, FFJ1=0.3,
                         MFJ2=0.45, MFJ1=0.45, RFJ2=0.55, RFJ1=0.6, LFJ4=0.1, LFJ2=0.7, LFJ1=0.7),
    # Flat hand.
    "handclap": posture(THJ3=0.1),
    # Index straight, the other fingers curled into the palm, thumb tucked over them.
    "et": posture(THJ4=0.4, THJ3=0.9, THJ1=0.4, THJ0=-0.3, MFJ2=1.0, MFJ1=1.3,
                  RFJ2=1.1, RFJ1=1.3, LFJ4=0.2, LFJ2=1.2, LFJ1=1.2),
}  # fmt: skip
"""Actor hand posture at contact (minimum-jerk target of the finger closure)."""

SQUEEZE = posture(FFJ2=0.15, FFJ1=0.2, MFJ2=0.15, MFJ1=0.2, RFJ2=0.15, RFJ1=0.2,
                  LFJ2=0.15, LFJ1=0.2, THJ1=0.1)  # fmt: skip
"""Extra handshake closure during contact."""

TARGET_POSTURE = {
    "handshake": posture(WRJ1=-0.15, THJ3=0.6, THJ1=0.45, FFJ2=0.2, FFJ1=0.2, MFJ2=0.3,
                         MFJ1=0.4, RFJ2=0.4, RFJ1=0.5, LFJ2=0.5, LFJ1=0.6),
    "handclap": posture(THJ3=0.1),
    "et": posture(THJ4=0.4, THJ3=0.9, THJ1=0.4, THJ0=-0.3, MFJ2=1.0, MFJ1=1.4,
                  RFJ2=1.1, RFJ1=1.4, LFJ4=0.2, LFJ2=1.2, LFJ1=1.3),
}  # fmt: skip
"""Static target posture per task."""

HANDSHAKE_CROSSING = np.radians(45.0)
"""Angle between the two hands' finger directions (in the shared palm plane) beyond
antiparallel: each hand's fingers reach round the other's little-finger edge."""
THUMB_WEB = np.array([0.03, 0.0, 0.03])
"""Web between thumb and index, in the palm frame: ~3 cm towards the thumb and the
fingers from the palm centre (between thbase and ffknuckle of the model)."""
ET_ROLL = np.radians(25.0)
"""Roll of the pointing hand about its index (semi-pronated forearm)."""


def _columns(x, y, z) -> np.ndarray:
    return np.stack([x, y, z], axis=-1).astype(np.float64)


def _rodrigues(w: np.ndarray) -> np.ndarray:
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


def _point(joints: np.ndarray, name: str) -> np.ndarray:
    """Palm-frame position (3,) of a HAND_POINTS entry for a (20,) posture."""
    return hand_kinematics.forward_kinematics(joints).points[HAND_POINTS.index(name)]


def contact_pose(
    task: str, actor: np.ndarray, target: np.ndarray, tilt: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Designed actor palm pose at contact, in the target palm frame.

    Args:
      task: one of mocap.TASKS.
      actor, target: (20,) postures at contact (used for the fingertip geometry).
      tilt: (3, 3) optional rotation applied in the actor palm frame before the position
        is solved, so that the defining contact (webs, index tips) still holds.
    Returns:
      position (3,) of the actor palm centre, rotation (3, 3) of the actor palm axes.
    """
    tilt = np.eye(3) if tilt is None else tilt
    y = np.array([0.0, 1.0, 0.0])
    if task == "handshake":
        # Palms face (y_a = -y_t), fingers crossed in the palm plane; thumb webs meet.
        c, s = np.cos(HANDSHAKE_CROSSING), np.sin(HANDSHAKE_CROSSING)
        z_a = np.array([-s, 0.0, -c])
        rot = _columns(np.cross(-y, z_a), -y, z_a) @ tilt
        return THUMB_WEB - PALM_GAP * y - rot @ THUMB_WEB, rot
    if task == "handclap":
        # Palms flat together, fingers antiparallel and aligned (thumbs on the same side);
        # symmetric overlap: each hand's fingertips rest on the other's upper palm, halfway
        # between its centre and its knuckle line.
        rot = _columns([1.0, 0.0, 0.0], -y, [0.0, 0.0, -1.0]) @ tilt
        knuckles = 0.095 - PALM_CENTER[2]  # ffknuckle height above the palm centre
        reach = 0.5 * knuckles + _point(actor, "mftip")[2]
        return np.array([0.0, -PALM_GAP, reach]), rot
    if task == "et":
        # Index points into the target's index pad (+y_t); palm turned to the target's wrist
        # side, then rolled about the index. Tips one pad thickness apart.
        base = _columns([-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], y)
        rot = base @ _rodrigues(np.array([0.0, 0.0, ET_ROLL])) @ tilt
        tip_goal = _point(target, "fftip") - PAD_GAP * y
        return tip_goal - rot @ _point(actor, "fftip"), rot
    raise mocap.MocapError(f"unknown task {task!r}; valid tasks: {', '.join(mocap.TASKS)}")


CONTACT_JITTER = {
    "handshake": np.array([0.008, 0.002, 0.008]),
    "handclap": np.array([0.008, 0.002, 0.008]),
    "et": np.array([0.003, 0.003, 0.003]),
}
"""Standard deviation of the contact position per target-frame axis, metres: slides
along the palms but little along their normal (y); E.T. keeps the tips on."""

RETREAT = {
    # Direction (target frame) from the contact to the start of the approach, before the
    # actor's own backward (-z_a) component is added: out of the target's palm side.
    "handshake": np.array([0.0, -0.6, 0.0]),
    "handclap": np.array([0.0, -0.6, 0.0]),
    "et": np.array([0.0, 0.0, 0.3]),
}


def generate(
    task: str, index: int, rng: np.random.Generator, fps: float = FPS
) -> mocap.Demonstration:
    """One synthetic demonstration of ``task`` (draws from ``rng``)."""
    actor_goal = ACTOR_POSTURE[task] * rng.uniform(0.85, 1.1)
    target = hand_kinematics.clip_to_range(TARGET_POSTURE[task] + rng.normal(0.0, 0.03, 20))
    actor_goal = hand_kinematics.clip_to_range(actor_goal)
    tilt = _rodrigues(rng.normal(0.0, np.radians(3.0), 3))
    pos_c, rot_c = contact_pose(task, actor_goal, target, tilt)
    pos_c = pos_c + rng.normal(0.0, 1.0, 3) * CONTACT_JITTER[task]

    approach_s = rng.uniform(1.1, 1.7)
    hold_s = rng.uniform(0.4, 0.9)
    begin = int(np.rint(approach_s * fps))
    num_frames = begin + int(np.rint(hold_s * fps)) + 1
    t = np.arange(num_frames)

    # Start: backed off along the actor's forearm and out of the target's way.
    retreat = RETREAT[task] - rot_c[:, 2] + rng.normal(0.0, 0.1, 3)
    retreat /= np.linalg.norm(retreat)
    pos_0 = pos_c + rng.uniform(0.30, 0.45) * retreat
    turn = rng.normal(0.0, 1.0, 3)
    turn *= np.radians(rng.uniform(20.0, 40.0)) / np.linalg.norm(turn)

    s = minimum_jerk(t / begin)  # (T,)
    pos = pos_0 + s[:, None] * (pos_c - pos_0)
    rot = np.stack([rot_c @ _rodrigues((1.0 - si) * turn) for si in s])

    # Fingers: close during the second part of the approach.
    close_from = rng.uniform(0.3, 0.6) * begin
    closure = minimum_jerk((t - close_from) / (begin - close_from))
    actor = RELAXED + closure[:, None] * (actor_goal - RELAXED)
    if task == "handshake":
        squeeze = minimum_jerk((t - begin) / (0.25 * fps)) * rng.uniform(0.7, 1.2)
        actor = actor + squeeze[:, None] * SQUEEZE
    return mocap.build_demonstration(
        task=task,
        name=f"{task}/synthetic/{index:02d}",
        source="synthetic",
        fps=fps,
        actor_joints=actor,
        target_joints=np.broadcast_to(target, (num_frames, 20)),
        actor_palm_pos=pos,
        actor_palm_rot=rot,
        contact_begin=begin,
        contact_end=num_frames - 1,
    )


def generate_task(task: str, num: int = NUM_DEMOS, seed: int = SEED) -> list[mocap.Demonstration]:
    """``num`` demonstrations of ``task``; deterministic for a given seed."""
    rng = np.random.default_rng([seed, mocap.TASKS.index(task)])
    return [generate(task, i, rng) for i in range(num)]


def write_all(
    out: Path = mocap.SYNTHETIC_PATH, num: int = NUM_DEMOS, seed: int = SEED
) -> list[Path]:
    """Generate every task and write ``out/<task>.npz``."""
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for task in mocap.TASKS:
        file = out / f"{task}.npz"
        mocap.save_npz(generate_task(task, num, seed), file)
        files.append(file)
    return files


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=mocap.SYNTHETIC_PATH, help="output folder")
    parser.add_argument("--num", type=int, default=NUM_DEMOS, help="demonstrations per task")
    parser.add_argument("--seed", type=int, default=SEED, help="random seed")
    args = parser.parse_args(argv)
    for file in write_all(args.out, args.num, args.seed):
        print(f"wrote {file}")


if __name__ == "__main__":
    main()

"""Names, orders and the MJCF source of the Shadow Dexterous Hand.

One place for every index convention of the project, so that the mocap loader,
the reward parameters, the scene and the environment agree without talking to
each other:

* ``HAND_JOINTS`` -- the 20 actuated hand joints in the order of the authors'
  actuators, which is also the column order of the mocap joint-angle arrays.
  The agent's 24 controls are ``ARM_JOINTS + HAND_JOINTS``.
* ``FINGERTIPS`` -- the 5 fingertip sites in the order used for every
  ``(..., 5, 3)`` fingertip array.
* ``HAND_POINTS`` -- palm followed by the 5 fingertips: ``(..., 6, 3)`` arrays.
* ``CONTACT_SENSORS`` -- the 15 contact sensors, 3 per finger
  (distal, middle, proximal), fingers in ``FINGERTIPS`` order.

The hand model is the one shipped by ``gymnasium-robotics`` (Apache-2.0); its
names carry the prefix ``robot0:`` which :func:`hand_name` adds.
"""

from __future__ import annotations

import importlib.util
import os

import jax
import jax.numpy as jnp
import numpy as np

FINGERS = ("th", "ff", "mf", "rf", "lf")
"""Thumb, first, middle, ring, little finger: the order of every per-finger array."""

ARM_JOINTS = ("shoulder_pan", "shoulder_lift", "upper_arm_roll", "elbow_flex")
"""The 4 arm joints that carry the agent hand (scenes/arm.xml)."""

HAND_JOINTS = (
    "WRJ1", "WRJ0",
    "THJ4", "THJ3", "THJ2", "THJ1", "THJ0",
    "FFJ3", "FFJ2", "FFJ1",
    "MFJ3", "MFJ2", "MFJ1",
    "LFJ4", "LFJ3", "LFJ2", "LFJ1",
    "RFJ3", "RFJ2", "RFJ1",
)  # fmt: skip
"""The 20 actuated hand joints, in the authors' actuator (= mocap column) order."""

COUPLED_DISTAL_JOINTS = {"FFJ0": "FFJ1", "MFJ0": "MFJ1", "RFJ0": "RFJ1", "LFJ0": "LFJ1"}
"""Distal joints driven by the middle joint's tendon (not actuated, not recorded)."""

ALL_HAND_JOINTS = (
    "WRJ1", "WRJ0",
    "FFJ3", "FFJ2", "FFJ1", "FFJ0",
    "MFJ3", "MFJ2", "MFJ1", "MFJ0",
    "RFJ3", "RFJ2", "RFJ1", "RFJ0",
    "LFJ4", "LFJ3", "LFJ2", "LFJ1", "LFJ0",
    "THJ4", "THJ3", "THJ2", "THJ1", "THJ0",
)  # fmt: skip
"""All 24 hand joints in kinematic-tree order (the order of qpos in the hand model)."""

FINGERTIPS = tuple(f"{f}tip" for f in FINGERS)
"""Fingertip site names (without prefix), in ``FINGERS`` order."""

HAND_POINTS = ("palm",) + FINGERTIPS
"""Palm centre followed by the fingertips: the rows of every ``(..., 6, 3)`` array."""

PHALANGES = ("distal", "middle", "proximal")
"""Contact-sensor segments of a finger, tip first."""

CONTACT_SENSORS = tuple(f"{f}_{p}" for f in FINGERS for p in PHALANGES)
"""The 15 contact sensors: ``th_distal, th_middle, th_proximal, ff_distal, ...``."""

PHALANX_BODY = {
    (f, p): f"{f}{p}" for f in ("ff", "mf", "rf", "lf") for p in PHALANGES
} | {("th", "distal"): "thdistal", ("th", "middle"): "thmiddle", ("th", "proximal"): "thproximal"}
"""Hand body (without prefix) that carries each contact sensor's collision geom."""

PREFIX = "robot0:"


def hand_name(name: str) -> str:
    """Element name in the gymnasium-robotics MJCF, e.g. ``'FFJ3' -> 'robot0:FFJ3'``."""
    return PREFIX + name


def sensor_index(name: str) -> int:
    """Index of a contact sensor (e.g. ``'ff_distal'``) in ``CONTACT_SENSORS``."""
    try:
        return CONTACT_SENSORS.index(name)
    except ValueError:
        raise ValueError(
            f"unknown contact sensor {name!r}; expected one of {', '.join(CONTACT_SENSORS)}"
        ) from None


def asset_dir() -> str:
    """Folder of the Shadow hand MJCF inside the installed gymnasium-robotics package.

    Located without importing the package (its import registers dozens of gym
    environments and prints deprecation notices).
    """
    spec = importlib.util.find_spec("gymnasium_robotics")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError(
            "the Shadow hand model comes from the 'gymnasium-robotics' package; "
            "install the project with `pip install -e .`"
        )
    path = os.path.join(spec.submodule_search_locations[0], "envs", "assets", "hand")
    if not os.path.isfile(os.path.join(path, "robot.xml")):
        raise FileNotFoundError(f"Shadow hand MJCF not found at {path}/robot.xml")
    return path


DISTAL_COUPLING = 0.00805 / 0.00705
"""J0 = DISTAL_COUPLING * J1 for the four fingers: the ratio of the moment arms of the
coupling tendon ``T_xxJ1c`` in the hand model, which the scene turns into a joint
equality (one constraint row instead of a tendon and its limits)."""

PALM_CENTER = (0.011, 0.0, 0.038)
"""Palm centre in the palm body frame (centre of the main palm collision box): the
origin of the 'palm frame' in which demonstrations express positions."""


def full_hand_angles(angles):
    """Expand actuated angles to all hand joints.

    Args:
      angles: (..., 20) in ``HAND_JOINTS`` order (NumPy or jnp).
    Returns:
      (..., 24) in ``ALL_HAND_JOINTS`` order; each distal J0 follows its J1 through
      ``DISTAL_COUPLING`` (not clipped: callers clip to the joint range they model).
    """
    idx = {n: i for i, n in enumerate(HAND_JOINTS)}
    cols = []
    for name in ALL_HAND_JOINTS:
        if name in COUPLED_DISTAL_JOINTS:
            cols.append(angles[..., idx[COUPLED_DISTAL_JOINTS[name]]] * DISTAL_COUPLING)
        else:
            cols.append(angles[..., idx[name]])
    xp = jnp if isinstance(angles, jax.Array) else np
    return xp.stack(cols, axis=-1)

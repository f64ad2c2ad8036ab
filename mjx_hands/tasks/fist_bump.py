"""Fist bump: two fists meet knuckles first, thumbs on the same side.

The fourth interaction, added as one module: the paper did not study it, so it has no
authors' weights, target box or ratings and trains with the project profile. Its
demonstrations come in through the importer, as a lab's would: ``mocap_data/fist_bump/``
holds BVH takes drawn from this module's :data:`DESIGN` (synthetic, said plainly) and
``mocap_data/fist_bump.npz`` is what ``import_mocap`` made of them::

    python -m mjx_hands.synthetic_demos --task fist_bump   # rewrite the takes, import them

Success: the middle knuckle, or the index and ring knuckles together, touch the other
hand: the fist's face, not an edge (the proximal phalanges face forward in a fist).
"""

from __future__ import annotations

import numpy as np

from mjx_hands.demo_design import UP, columns, link_position, posture
from mjx_hands.tasks.spec import THUMB_UP_PALM_FORWARD, SyntheticDesign, TaskSpec

FIST = posture(THJ4=0.9, THJ3=1.1, THJ1=0.4, THJ0=-0.5, FFJ2=1.55, FFJ1=1.5, MFJ2=1.55,
               MFJ1=1.5, RFJ2=1.55, RFJ1=1.5, LFJ4=0.3, LFJ2=1.55, LFJ1=1.5)  # fmt: skip
"""A closed fist, the thumb over the index and middle fingers."""
KNUCKLE_RADIUS = 0.01
"""Half the thickness of a proximal phalanx (its collision capsule's radius), metres."""


def _knuckle_face(joints: np.ndarray) -> np.ndarray:
    """The middle finger's proximal phalanx, halfway along, on its back: the centre of a
    fist's face (palm frame)."""
    mid = 0.5 * (link_position(joints, "mfproximal") + link_position(joints, "mfmiddle"))
    return mid + KNUCKLE_RADIUS * np.array([0.0, 0.0, 1.0])


def contact_pose(actor: np.ndarray, target: np.ndarray, tilt: np.ndarray):
    """Fists face each other (z_a = -z_t), thumbs on the same side, the knuckle faces'
    centres together."""
    rot = columns([1.0, 0.0, 0.0], -UP, [0.0, 0.0, -1.0]) @ tilt
    return _knuckle_face(target) - rot @ _knuckle_face(actor), rot


DESIGN = SyntheticDesign(
    actor_posture=FIST,
    target_posture=FIST,
    contact_pose=contact_pose,
    contact_jitter=(0.006, 0.006, 0.002),  # across the fist's face, little along it
    retreat=(0.0, 0.2, 0.0),  # straight back, a little from above
)
"""The design of the generated takes."""

SPEC = TaskSpec(
    name="fist_bump",
    episode_length=75,
    required_contacts=("ff_proximal", "mf_proximal", "rf_proximal"),
    contact_rotation=THUMB_UP_PALM_FORWARD,
    contact_groups=(("mf_proximal", "ff_proximal"), ("mf_proximal", "rf_proximal")),
    synthetic=DESIGN,
    synthetic_takes="bvh",
)

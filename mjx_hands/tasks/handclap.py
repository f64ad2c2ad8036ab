"""Hand clap: palms flat together, fingers antiparallel and aligned.

Success: the distal or middle phalanx of every finger touches the other hand, and the
thumb stays off it (the authors charge for the thumb's distal and middle sensors).
Reward knobs, weights, target box and demonstration rows are the authors'.
"""

from __future__ import annotations

import numpy as np

from mjx_hands.demo_design import PALM_GAP, UP, columns, point, posture
from mjx_hands.shadow_hand import PALM_CENTER
from mjx_hands.tasks.spec import (
    AUTHORS_SLIDE_AXES,
    THUMB_UP_PALM_FORWARD,
    AuthorsWeights,
    SyntheticDesign,
    TargetBox,
    TaskSpec,
)

GROUPS = tuple((f"{f}_distal", f"{f}_middle") for f in ("ff", "mf", "rf", "lf"))


def contact_pose(actor: np.ndarray, target: np.ndarray, tilt: np.ndarray):
    """Palms flat together, fingers antiparallel and aligned (thumbs on the same side);
    symmetric overlap: each hand's fingertips rest on the other's upper palm, halfway
    between its centre and its knuckle line."""
    rot = columns([1.0, 0.0, 0.0], -UP, [0.0, 0.0, -1.0]) @ tilt
    knuckles = 0.095 - PALM_CENTER[2]  # ffknuckle height above the palm centre
    reach = 0.5 * knuckles + point(actor, "mftip")[2]
    return np.array([0.0, -PALM_GAP, reach]), rot


SPEC = TaskSpec(
    name="handclap",
    episode_length=75,
    required_contacts=tuple(s for group in GROUPS for s in group),
    contact_rotation=THUMB_UP_PALM_FORWARD,
    contact_groups=GROUPS,
    authors_demos=(1, 2, 3, 5, 7, 8),
    authors_knobs=(("K_p", 1.0), ("K_c", 0.1), ("K_alpha", 0.5)),
    authors_weights=(
        ("full", AuthorsWeights(W_pos=1, W_f=0.1, W_ang=0.5)),
        ("baseline1", AuthorsWeights(W_pos=1, W_f=0.1, W_ang=0.25)),
        ("baseline2", AuthorsWeights(W_pos=1, W_f=0.0, W_ang=0.2)),
    ),
    authors_forbidden_contacts=("th_distal", "th_middle"),
    authors_target_box=TargetBox(
        low=(-0.05, -0.05, 0), high=(0.05, 0.05, 0.15), axes=tuple(zip(*AUTHORS_SLIDE_AXES))
    ),
    synthetic=SyntheticDesign(
        actor_posture=posture(THJ3=0.1),  # flat hand
        target_posture=posture(THJ3=0.1),
        contact_pose=contact_pose,
        contact_jitter=(0.008, 0.002, 0.008),
        retreat=(0.0, -0.6, 0.0),
        seed_key=1,  # the committed mocap_data/handclap.npz was drawn with this key
    ),
    paper_raters_score=1.44,
)

"""E.T. finger touch: the index tips meet, the other fingers curled.

Success: the index's distal phalanx touches the other hand. Reward knobs, weights, the
tilted target box with its extra 4-7 cm along the mount (the authors' "feasible
approaching angle") and demonstration rows are the authors'.
"""

from __future__ import annotations

import numpy as np

from mjx_hands.demo_design import PAD_GAP, UP, columns, point, posture, rodrigues
from mjx_hands.tasks.spec import AuthorsWeights, SyntheticDesign, TargetBox, TaskSpec

AXES = ((-0.878, 0, 0.479), (0, -1, 0), (0.479, 0, 0.878))
"""The authors' slide joints HMJX, HMJY, HMJZ (rows), along their tilted mount."""
ROLL = np.radians(25.0)
"""Roll of the pointing hand about its index (semi-pronated forearm)."""
CURLED = {"THJ4": 0.4, "THJ3": 0.9, "THJ1": 0.4, "THJ0": -0.3, "MFJ2": 1.0, "RFJ2": 1.1,
          "LFJ4": 0.2, "LFJ2": 1.2}  # fmt: skip
"""The fingers other than the index curled into the palm, the thumb tucked over them."""


def contact_pose(actor: np.ndarray, target: np.ndarray, tilt: np.ndarray):
    """Index points into the target's index pad (+y_t); palm turned to the target's wrist
    side, then rolled about the index. Tips one pad thickness apart."""
    base = columns([-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], UP)
    rot = base @ rodrigues(np.array([0.0, 0.0, ROLL])) @ tilt
    tip_goal = point(target, "fftip") - PAD_GAP * UP
    return tip_goal - rot @ point(actor, "fftip"), rot


SPEC = TaskSpec(
    name="et",
    episode_length=75,
    required_contacts=("ff_distal",),
    # The palm faces down at contact.
    contact_rotation=((0, 0, 1), (1, 0, 0), (0, 1, 0)),
    authors_demos=(0, 1, 3, 4),
    authors_knobs=(("K_p", 6.0), ("K_c", 0.5), ("K_alpha", 0.2)),
    authors_weights=(
        ("full", AuthorsWeights(W_pos=6, W_f=0.5, W_ang=0.2)),
        ("baseline1", AuthorsWeights(W_pos=4, W_f=0.2, W_ang=0.5)),
        ("baseline2", AuthorsWeights(W_pos=1, W_f=0.0, W_ang=0.2)),
    ),
    authors_target_box=TargetBox(
        low=(0, -0.05, 0), high=(0.05, 0.05, 0.10), axes=tuple(zip(*AXES)),
        shift_low=(0, 0, 0.04), shift_high=(0, 0, 0.07),
    ),
    synthetic=SyntheticDesign(
        # Index straight, the other fingers curled into the palm, thumb tucked over them.
        actor_posture=posture(**CURLED, MFJ1=1.3, RFJ1=1.3, LFJ1=1.2),
        target_posture=posture(**CURLED, MFJ1=1.4, RFJ1=1.4, LFJ1=1.3),
        contact_pose=contact_pose,
        contact_jitter=(0.003, 0.003, 0.003),  # keeps the tips on
        retreat=(0.0, 0.0, 0.3),
        seed_key=2,  # the committed mocap_data/et.npz was drawn with this key
    ),
    paper_raters_score=0.07,
)  # fmt: skip

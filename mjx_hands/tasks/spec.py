"""What a task module states: :class:`TaskSpec` and the records it is made of.

A task is one module of ``mjx_hands.tasks`` holding ``SPEC = TaskSpec(...)``; the
package's ``MODULES`` line registers it. Why each fact is what it is lives with its
reader: required contacts in ``reward_params`` (the success rule and its evidence),
contact rotations in ``env.place_target``, episode lengths and the control period in the
paper.
"""

from __future__ import annotations

import dataclasses
import zlib
from collections.abc import Callable

import numpy as np

CONTROL_DT = 0.04
"""The paper's control period, seconds (every task's)."""


THUMB_UP_PALM_FORWARD = ((0, 0, 1), (0, -1, 0), (1, 0, 0))
"""A ``TaskSpec.contact_rotation``: thumb up, palm facing +y, fingers forward (the
handshake's and the clap's agent palm at contact)."""
AUTHORS_SLIDE_AXES = ((-1, 0, 0), (0, 0, 1), (0, 1, 0))
"""The authors' target slide joints HMJX, HMJY, HMJZ (rows) for targets mounted upright:
towards the agent, up, sideways."""


@dataclasses.dataclass(frozen=True)
class AuthorsWeights:
    """One of the authors' reward configs (their ``config/<task>[_baseline<k>].yaml``)."""

    W_pos: float
    """Goal-position scale (K_p; Algorithm 1's point weights, closest point 1, times it)."""
    W_f: float
    """Charge per contact sensor off its goal (K_c in the penalty form)."""
    W_ang: float
    """Goal joint-angle weight, per joint and radian (K_alpha)."""
    W_ipos: float = 0.0
    """Imitation-position scale (absolute: times the point weights, closest point 1)."""
    W_iang: float = 0.0
    """Imitation joint-angle weight, per joint and radian (absolute)."""


@dataclasses.dataclass(frozen=True)
class TargetBox:
    """Where the target palm is drawn: ``centre + axes @ (U(low, high) + U(shift_low,
    shift_high))`` with ``axes`` (3, 3) of world directions as columns (metres)."""

    low: tuple[float, float, float]
    high: tuple[float, float, float]
    axes: tuple[tuple[float, ...], ...] = ((1, 0, 0), (0, 1, 0), (0, 0, 1))
    shift_low: tuple[float, float, float] = (0.0, 0.0, 0.0)
    shift_high: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @staticmethod
    def cube(half: tuple[float, float, float]) -> TargetBox:
        """The box ``±half`` along the world axes (the project's)."""
        return TargetBox(low=tuple(-h for h in half), high=tuple(half))


@dataclasses.dataclass(frozen=True)
class SyntheticDesign:
    """How the project draws a task's own demonstrations (``mjx_hands.synthetic_demos``):
    a minimum-jerk approach of the actor palm to a designed contact pose while the fingers
    close from ``demo_design.RELAXED`` to ``actor_posture``. Postures are (20,) radians in
    ``HAND_JOINTS`` order; vectors are in the target palm frame, metres."""

    actor_posture: np.ndarray
    """Actor hand posture at contact (the target of the finger closure)."""
    target_posture: np.ndarray
    """The static target hand's posture."""
    contact_pose: Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
    """``(actor (20,), target (20,), tilt (3, 3)) -> (position (3,), rotation (3, 3))`` of
    the actor palm at contact; ``tilt`` is applied in the actor palm frame first, so that
    the defining contact still holds."""
    contact_jitter: tuple[float, float, float]
    """Standard deviation of the contact position per target-frame axis."""
    retreat: tuple[float, float, float]
    """Direction from the contact to the start of the approach, before the actor's own
    backward (-z) component is added: out of the target's way."""
    squeeze: np.ndarray | None = None
    """Extra closure (20,) blended in during the first 0.25 s of contact (None: none)."""
    seed_key: int | None = None
    """Second entry of the generator's seed; None: a hash of the task's name."""


@dataclasses.dataclass(frozen=True)
class TaskSpec:
    """One interaction's fixed facts."""

    name: str
    episode_length: int
    """Control steps per episode (the paper's: 100 handshake, 75 otherwise)."""
    required_contacts: tuple[str, ...]
    """Contact sensors (``shadow_hand.CONTACT_SENSORS`` names) that must all touch the
    other hand for the episode to succeed."""
    contact_rotation: tuple[tuple[float, ...], ...]
    """Agent palm orientation at the demonstrated contact (3, 3): columns are the palm
    body's x (thumb side), y (back of the hand) and z (fingers) axes in the world. The
    agent stands at the origin facing +x; at zero arm angles its palm faces +y with the
    thumb up (the handshake and clap pose); for E.T. the palm faces down."""
    control_dt: float = CONTROL_DT
    """Control period, seconds."""
    contact_groups: tuple[tuple[str, ...], ...] = ()
    """Success needs one touching sensor of every group; () makes every required
    sensor its own group (all must touch)."""
    authors_demos: tuple[int, ...] = ()
    """Rows of the authors' release (``interaction_t``) their environment trained on."""
    authors_knobs: tuple[tuple[str, float], ...] = ()
    """The reward knobs the authors set for this task (``RewardWeights`` field, value):
    their config's ``W_pos`` (K_p), ``W_f`` (K_c: their force term charges W_f per
    required sensor out of contact, a reward of K_c per sensor in contact up to a
    constant) and ``W_ang`` (K_alpha, per joint and radian)."""
    reward_knobs: tuple[tuple[str, float], ...] = ()
    """The knobs this task trains with where they differ from ``RewardWeights``'
    defaults, chosen by training both sets (benchmarks/results/reward_knobs.md)."""
    authors_weights: tuple[tuple[str, AuthorsWeights], ...] = ()
    """The authors' reward configs of this task by reward (``full``: their main config,
    ``baseline1``, ``baseline2``): the paper profile's weights."""
    authors_forbidden_contacts: tuple[str, ...] = ()
    """Sensors the authors charge for touching (their ``FORCE_GOALS`` 0)."""
    authors_target_box: TargetBox | None = None
    """The authors' box of target positions (their ``training_range`` of the target
    hand's slide joints, along those joints' world directions), centred as the project
    centres its target."""

    synthetic: SyntheticDesign | None = None
    """The design of the project's own demonstrations (``mocap_data/<name>.npz``); None
    for a task whose demonstrations come only from recordings."""
    synthetic_takes: str | None = None
    """None: the designed demonstrations go straight into ``mocap_data/<name>.npz``;
    "bvh" or "motive": they are written as takes of that format into
    ``mocap_data/<name>/`` and imported from there, as a lab's recordings would be."""
    paper_raters_score: float | None = None
    """The paper's Table I: mean rating in favour of the imitation-trained policy (-2..2);
    None for a task the paper did not study."""

    @property
    def in_authors_release(self) -> bool:
        """Whether the authors' recordings hold this task (their ``authors_demos``)."""
        return bool(self.authors_demos)

    @property
    def contact_rotation_matrix(self) -> np.ndarray:
        return np.array(self.contact_rotation, np.float64)

    @property
    def success_groups(self) -> tuple[tuple[str, ...], ...]:
        return self.contact_groups or tuple((s,) for s in self.required_contacts)


def name_key(name: str) -> int:
    """A stable 32-bit seed entry from a task's name (independent of registry order)."""
    return zlib.crc32(name.encode())

"""The task registry: every per-task fact the other modules read, in one place.

``TASKS`` names the interactions; :func:`spec` returns a task's :class:`TaskSpec`.
Why each fact is what it is lives with its reader: required contacts in
``reward_params`` (the success rule and its evidence), contact rotations in
``env.place_target``, episode lengths and the control period in the paper.
"""

from __future__ import annotations

import dataclasses

import numpy as np

CONTROL_DT = 0.04
"""The paper's control period, seconds (every task's)."""


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

    @property
    def contact_rotation_matrix(self) -> np.ndarray:
        return np.array(self.contact_rotation, np.float64)

    @property
    def success_groups(self) -> tuple[tuple[str, ...], ...]:
        return self.contact_groups or tuple((s,) for s in self.required_contacts)


_HANDSHAKE_ROTATION = ((0, 0, 1), (0, -1, 0), (1, 0, 0))
_HANDSHAKE_AUTHORS_KNOBS = (("K_p", 4.0), ("K_c", 0.5), ("K_alpha", 0.0))
# The authors' configs: W_pos, W_f, W_ang (W_ipos, W_iang) of config/<task>.yaml and
# <task>_baseline{1,2}.yaml; target boxes of interactions/<task>.py (training_range of
# the slide joints HMJX/Y/Z: towards the agent (-x), up (+z) and sideways (+y) for the
# handshake and clap; along their tilted mount for E.T., which also moves 4-7 cm more
# along its third axis, hri_env.py's "feasible approaching angle").
_AUTHORS_HANDSHAKE = (
    ("full", AuthorsWeights(W_pos=4, W_f=0.5, W_ang=0.0)),
    ("baseline1", AuthorsWeights(W_pos=4, W_f=0.17, W_ang=0.0)),
    ("baseline2", AuthorsWeights(W_pos=1, W_f=0.0, W_ang=0.2, W_ipos=1.0, W_iang=0.2)),
)
_AUTHORS_CLAP = (
    ("full", AuthorsWeights(W_pos=1, W_f=0.1, W_ang=0.5)),
    ("baseline1", AuthorsWeights(W_pos=1, W_f=0.1, W_ang=0.25)),
    ("baseline2", AuthorsWeights(W_pos=1, W_f=0.0, W_ang=0.2)),
)
_AUTHORS_ET = (
    ("full", AuthorsWeights(W_pos=6, W_f=0.5, W_ang=0.2)),
    ("baseline1", AuthorsWeights(W_pos=4, W_f=0.2, W_ang=0.5)),
    ("baseline2", AuthorsWeights(W_pos=1, W_f=0.0, W_ang=0.2)),
)
_TOWARDS_UP_SIDEWAYS = ((-1, 0, 0), (0, 0, 1), (0, 1, 0))  # rows: HMJX, HMJY, HMJZ
_ET_AXES = ((-0.878, 0, 0.479), (0, -1, 0), (0.479, 0, 0.878))  # rows: HMJX, HMJY, HMJZ
_CLAP_GROUPS = tuple((f"{f}_distal", f"{f}_middle") for f in ("ff", "mf", "rf", "lf"))
# Required contacts, success rules, demonstration subsets and reward knobs are the
# authors' (their configs' TOUCH_SENSORS / FORCE_GOALS, success rule, demo lists and
# W_pos / W_f / W_ang; evidence in benchmarks/results/fidelity.md and reward_knobs.md).
REGISTRY = {
    "handshake": TaskSpec(
        name="handshake",
        episode_length=100,
        required_contacts=("th_middle", "ff_middle", "mf_middle", "rf_middle", "lf_middle"),
        contact_rotation=_HANDSHAKE_ROTATION,
        authors_demos=(0, 1, 2, 7, 8, 9),
        authors_knobs=_HANDSHAKE_AUTHORS_KNOBS,
        # The authors' knobs: 0.66 at the end after 45 epochs against 0.17 +- 0.08.
        reward_knobs=_HANDSHAKE_AUTHORS_KNOBS,
        authors_weights=_AUTHORS_HANDSHAKE,
        authors_target_box=TargetBox(
            low=(0, -0.05, 0), high=(0.05, 0.05, 0.10),
            axes=tuple(zip(*_TOWARDS_UP_SIDEWAYS)),
        ),
    ),
    "handclap": TaskSpec(
        name="handclap",
        episode_length=75,
        required_contacts=tuple(s for group in _CLAP_GROUPS for s in group),
        contact_rotation=_HANDSHAKE_ROTATION,
        contact_groups=_CLAP_GROUPS,
        authors_demos=(1, 2, 3, 5, 7, 8),
        authors_knobs=(("K_p", 1.0), ("K_c", 0.1), ("K_alpha", 0.5)),
        authors_weights=_AUTHORS_CLAP,
        authors_forbidden_contacts=("th_distal", "th_middle"),
        authors_target_box=TargetBox(
            low=(-0.05, -0.05, 0), high=(0.05, 0.05, 0.15),
            axes=tuple(zip(*_TOWARDS_UP_SIDEWAYS)),
        ),
    ),
    "et": TaskSpec(
        name="et",
        episode_length=75,
        required_contacts=("ff_distal",),
        contact_rotation=((0, 0, 1), (1, 0, 0), (0, 1, 0)),
        authors_demos=(0, 1, 3, 4),
        authors_knobs=(("K_p", 6.0), ("K_c", 0.5), ("K_alpha", 0.2)),
        authors_weights=_AUTHORS_ET,
        authors_target_box=TargetBox(
            low=(0, -0.05, 0), high=(0.05, 0.05, 0.10),
            axes=tuple(zip(*_ET_AXES)),
            shift_low=(0, 0, 0.04), shift_high=(0, 0, 0.07),
        ),
    ),
}  # fmt: skip
TASKS = tuple(REGISTRY)


def spec(task: str) -> TaskSpec:
    """The registered facts of ``task``; a clear error for an unknown name."""
    try:
        return REGISTRY[task]
    except KeyError:
        raise ValueError(f"unknown task {task!r}; expected one of {', '.join(TASKS)}") from None

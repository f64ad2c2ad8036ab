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
    defaults, chosen by training both sets (benchmarks/RESULTS.md, "Reward knobs")."""

    @property
    def contact_rotation_matrix(self) -> np.ndarray:
        return np.array(self.contact_rotation, np.float64)

    @property
    def success_groups(self) -> tuple[tuple[str, ...], ...]:
        return self.contact_groups or tuple((s,) for s in self.required_contacts)


_HANDSHAKE_ROTATION = ((0, 0, 1), (0, -1, 0), (1, 0, 0))
_HANDSHAKE_AUTHORS_KNOBS = (("K_p", 4.0), ("K_c", 0.5), ("K_alpha", 0.0))
_CLAP_GROUPS = tuple((f"{f}_distal", f"{f}_middle") for f in ("ff", "mf", "rf", "lf"))
# Required contacts, success rules, demonstration subsets and reward knobs are the
# authors' (their configs' TOUCH_SENSORS / FORCE_GOALS, success rule, demo lists and
# W_pos / W_f / W_ang; evidence in benchmarks/RESULTS.md, "Fidelity to the authors'
# environment" and "Reward knobs").
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
    ),
    "handclap": TaskSpec(
        name="handclap",
        episode_length=75,
        required_contacts=tuple(s for group in _CLAP_GROUPS for s in group),
        contact_rotation=_HANDSHAKE_ROTATION,
        contact_groups=_CLAP_GROUPS,
        authors_demos=(1, 2, 3, 5, 7, 8),
        authors_knobs=(("K_p", 1.0), ("K_c", 0.1), ("K_alpha", 0.5)),
    ),
    "et": TaskSpec(
        name="et",
        episode_length=75,
        required_contacts=("ff_distal",),
        contact_rotation=((0, 0, 1), (1, 0, 0), (0, 1, 0)),
        authors_demos=(0, 1, 3, 4),
        authors_knobs=(("K_p", 6.0), ("K_c", 0.5), ("K_alpha", 0.2)),
    ),
}  # fmt: skip
TASKS = tuple(REGISTRY)


def spec(task: str) -> TaskSpec:
    """The registered facts of ``task``; a clear error for an unknown name."""
    try:
        return REGISTRY[task]
    except KeyError:
        raise ValueError(f"unknown task {task!r}; expected one of {', '.join(TASKS)}") from None

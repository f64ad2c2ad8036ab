"""Reward parameters from a demonstration: Algorithm 1 of Christen et al. (ICRA 2019).

One human-human demonstration (a :class:`mjx_hands.mocap.Demonstration`) turns into
the goals, weights and imitation references of the paper's reward, expressed so that
the environment can evaluate them against the *simulated* target hand:

1. Distances ``d^{ij}_t = ||p^i_t - p^j_t||`` between every actor fingertip ``i`` and
   every target point ``j`` (``HAND_POINTS``: palm centre + 5 fingertips) for the
   frames of the contact window ``t in [contact_begin, contact_end]``. (Searching the
   whole approach picks, in several real handshakes, a frame before the hands meet:
   the closest fingertip pair is then not the interaction's contact.)
2. The closest approach ``(t_min, i_min, j_min) = argmin d^{ij}_t`` and ``d_min``.
3. Goals relative to target body ``j_min``: ``Δp^i = R_{j_min}^T (p^i - p^{j_min})`` at
   ``t_min`` for all 6 actor points; the environment places them on the simulated
   target hand (:func:`mjx_hands.rewards.goal_positions`). Goal angles are the
   actor's joint angles at ``t_min``.
4. Imitation references for ``t <= t_min``: the same offsets and the actor's joint
   angles along the demonstration, resampled to the control rate.
5. Weights: ``ω^i_p = K_p · d_min / d^{i j_min}_{t_min}`` (the closest fingertip
   gets ``K_p``, farther ones less), ``ω_α = K_α``, ``ω_a = K_a``, and
   ``ω_c = K_c`` on the task's required contact sensors.

Required contact sensors per task (``REQUIRED_CONTACTS``, names of
``shadow_hand.CONTACT_SENSORS``) are rewarded by ``K_c``; an episode succeeds when one
sensor of every success group touches (``success_group_mask``). Both are the
authors' (their environment's touch sensors and success rule):

* ``handshake``: the middle phalanges of all five fingers, each required -- the
  fingers and thumb wrap around the other hand. Following the demonstrations with a
  scripted controller never touches with the thumb's middle phalanx (0 of 64
  episodes on the recordings), but a policy trained without any thumb reward already
  does in 34 % of its episodes (``benchmarks/results/fidelity.md``).
* ``handclap``: distal or middle phalanx of each of the index, middle, ring and little
  fingers (four groups of two): flat fingers against the other's.
* ``et``: ``ff_distal`` -- index fingertip to index fingertip.

Time: demonstrations are captured at ``demo.fps`` Hz, the policy acts every ``dt``
seconds. Control step ``k`` corresponds to capture frame ``k·fps·dt`` (linear
interpolation between frames). The control step *of* a frame ``f`` is the last step at
or before it, ``floor(f / (fps·dt))``.

Everything here runs once on the host with NumPy; :func:`build_task_params` returns
the stacked pytree as ``jax.Array`` leaves with a leading ``n_demos`` axis.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Literal

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from mjx_hands import shadow_hand, tasks

if TYPE_CHECKING:  # mocap is only needed for the type; keep this module importable alone
    from mjx_hands.mocap import Demonstration

CONTROL_DT = tasks.CONTROL_DT
"""Default control period, seconds (the paper's 25 Hz policy)."""

DISTANCE_FLOOR = 1e-3
"""Metres. Distances in the position-weight ratio are floored here: a fingertip that
touches its target point (d -> 0) would otherwise blow up ``K_p·d_min/d``. 1 mm is
below marker precision, and flooring numerator and denominator alike keeps every
weight in ``(0, K_p]``."""

N_POINTS = len(shadow_hand.HAND_POINTS)  # 6: palm + 5 fingertips
N_JOINTS = len(shadow_hand.HAND_JOINTS)  # 20
N_SENSORS = len(shadow_hand.CONTACT_SENSORS)  # 15
N_CONTROLS = len(shadow_hand.ARM_JOINTS) + N_JOINTS  # 24
_TIPS = slice(1, N_POINTS)  # fingertip rows of a HAND_POINTS array

REQUIRED_CONTACTS = {name: task.required_contacts for name, task in tasks.REGISTRY.items()}
"""Contact sensors that must all touch the other hand for a task to succeed (the task
registry's; the evidence for each set is above)."""


N_GROUPS = 5
"""Rows of a success-group mask (one per finger at most); unused rows are empty."""


def required_contact_mask(task: str) -> np.ndarray:
    """(15,) bool over ``CONTACT_SENSORS``: the sensors ``task`` requires."""
    if task not in REQUIRED_CONTACTS:
        raise ValueError(f"unknown task {task!r}; expected one of {', '.join(REQUIRED_CONTACTS)}")
    mask = np.zeros(N_SENSORS, bool)
    mask[[shadow_hand.sensor_index(s) for s in REQUIRED_CONTACTS[task]]] = True
    return mask


def success_group_mask(task: str) -> np.ndarray:
    """(N_GROUPS, 15) bool: row g marks the sensors of ``task``'s success group g (one of
    them must touch); rows past the task's groups are empty and always satisfied."""
    required_contact_mask(task)  # names the task when it is unknown
    groups = tasks.spec(task).success_groups
    mask = np.zeros((N_GROUPS, N_SENSORS), bool)
    for g, group in enumerate(groups):
        mask[g, [shadow_hand.sensor_index(s) for s in group]] = True
    return mask


@dataclasses.dataclass(frozen=True)
class RewardWeights:
    """The paper's six reward knobs plus the switches of its ablations.

    Frozen and hashable, so it can be a static argument / closed-over config.
    """

    K_p: float = 1.0
    """Scale of the goal-position term; the closest fingertip's weight ``ω_p`` equals it."""
    K_alpha: float = 0.1
    """Weight of every hand joint in the goal-angle term (per radian)."""
    K_c: float = 0.2
    """Reward per required contact sensor in contact."""
    K_a: float = 0.0
    """Weight of every squared control in the reward's action penalty r_a. The paper
    states K_a = 1; the authors' code has no action term in the reward and instead
    penalises the actor by ``action_l2 = 1`` x mean squared action in its loss
    (``DDPGConfig.action_l2``, kept), so the reward adds none by default. (At 0.01, as
    before, r_a was 5-20 % of the per-step reward: ``benchmarks/results/fidelity.md``.)"""
    K_pI: float = 0.5
    """Scale of the imitation-position term relative to the position weights ``ω_p``."""
    K_alphaI: float = 0.5
    """Scale of the imitation-angle term relative to the angle weights ``ω_α``."""
    position_points: Literal["fingertips", "palm"] = "fingertips"
    """Actor points the position terms reward: the 5 fingertips (the paper's reward) or
    the palm centre only (Baseline 1)."""
    contact: bool = True
    """Reward contacts of the required sensors (Baseline 2 turns this off)."""
    imitation: bool = True
    """Add the imitation terms while the episode is before the demo's closest approach."""
    contact_form: Literal["bonus", "penalty"] = "bonus"
    """How ``K_c`` enters: ``bonus`` rewards ``K_c`` per required sensor in contact (the
    paper's text, r_c >= 0); ``penalty`` charges ``K_c`` per required sensor out of contact
    (the authors' code: ``W_f`` times the L1 error to their ``FORCE_GOALS``, r <= 0)."""
    forbidden_contacts: tuple[str, ...] = ()
    """Sensors (``CONTACT_SENSORS`` names) charged ``K_c`` while they touch (the authors'
    ``FORCE_GOALS`` 0: the clap's thumb)."""
    imitation_weights: Literal["relative", "absolute"] = "relative"
    """``relative``: ``K_pI`` and ``K_alphaI`` scale the goal terms' weights (ω_pI = K_pI ω_p,
    ω_αI = K_αI K_α, the project's); ``absolute``: they are the authors' ``W_ipos`` (times
    Algorithm 1's point weights, closest point 1) and ``W_iang`` (per joint and radian),
    independent of ``K_p`` and ``K_alpha``."""

    def __post_init__(self):
        if self.position_points not in ("fingertips", "palm"):
            raise ValueError(
                f"position_points must be 'fingertips' or 'palm', got {self.position_points!r}"
            )
        if self.contact_form not in ("bonus", "penalty"):
            raise ValueError(
                f"contact_form must be 'bonus' or 'penalty', got {self.contact_form!r}"
            )
        if self.imitation_weights not in ("relative", "absolute"):
            raise ValueError(
                "imitation_weights must be 'relative' or 'absolute', got "
                f"{self.imitation_weights!r}"
            )
        for name in self.forbidden_contacts:
            shadow_hand.sensor_index(name)  # names the sensor when it is unknown
        for name in KNOB_NAMES:
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")


REWARD_FORMS = {
    "full": {},
    "baseline1": {"position_points": "palm"},
    "baseline2": {"contact": False},
}
"""The reward's forms (the authors' config names; ``EnvConfig.reward``): ``full``, the
proposed reward; ``baseline1``, palm position instead of fingertips; ``baseline2``, no
contact term. Imitation is a switch of its own."""


@dataclasses.dataclass(frozen=True)
class RewardVariant:
    """A named reward of the paper's comparison: a form and whether imitation is on."""

    reward: str
    imitation: bool


VARIANTS: dict[str, RewardVariant] = {
    "full": RewardVariant("full", True),
    "no_imitation": RewardVariant("full", False),
    "baseline1": RewardVariant("baseline1", False),
    "baseline2": RewardVariant("baseline2", False),
    "baseline1_imitation": RewardVariant("baseline1", True),
    "baseline2_imitation": RewardVariant("baseline2", True),
}
"""The one vocabulary of reward variants (grids, reports, naturalness, the study):
``full`` is the paper's r = r_p + r_alpha + r_c + r_a + r_pI + r_alphaI;
``no_imitation`` the same without r_pI, r_alphaI (the authors' released main configs);
``baseline1`` and ``baseline2`` their forms without imitation, as the authors' baseline
configs; ``*_imitation`` with it."""


KNOB_NAMES = ("K_p", "K_alpha", "K_c", "K_a", "K_pI", "K_alphaI")


@dataclasses.dataclass(frozen=True)
class RewardKnobs:
    """The paper's six reward knobs, the part of the reward Algorithm 1 leaves to the
    user (meanings: :class:`RewardWeights`). None takes the task's own value
    (``tasks.TaskSpec.reward_knobs``, else :class:`RewardWeights`' default)."""

    K_p: float | None = None
    """Goal-position scale (the closest fingertip's weight)."""
    K_alpha: float | None = None
    """Goal joint-angle weight, per joint and radian."""
    K_c: float | None = None
    """Reward per required contact sensor in contact."""
    K_a: float | None = None
    """Weight of every squared control in the reward."""
    K_pI: float | None = None
    """Imitation-position scale, relative to the position weights."""
    K_alphaI: float | None = None
    """Imitation-angle scale, relative to the angle weights."""


def task_weights(task: str, knobs: RewardKnobs | None = None) -> RewardWeights:
    """The full reward's weights for ``task``: ``knobs`` where given, the task's own
    knobs elsewhere."""
    given = {k: v for k, v in dataclasses.asdict(knobs or RewardKnobs()).items() if v is not None}
    return RewardWeights(**(dict(tasks.spec(task).reward_knobs) | given))


def knobs_of(weights: RewardWeights) -> RewardKnobs:
    """The six knobs of ``weights``, as numbers."""
    return RewardKnobs(**{name: float(getattr(weights, name)) for name in KNOB_NAMES})


def task_knobs(task: str, knobs: RewardKnobs | None = None) -> RewardKnobs:
    """Every knob of ``task`` as a number (see :func:`task_weights`)."""
    return knobs_of(task_weights(task, knobs))


def reward_form(name: str, base: RewardWeights | None = None) -> RewardWeights:
    """``base``'s knobs in the reward form ``name`` (:data:`REWARD_FORMS`), imitation as
    ``base`` has it."""
    if name not in REWARD_FORMS:
        raise ValueError(f"unknown reward form {name!r}; expected one of {', '.join(REWARD_FORMS)}")
    return dataclasses.replace(base or RewardWeights(), **REWARD_FORMS[name])


def variant(name: str, base: RewardWeights | None = None) -> RewardWeights:
    """The weights of the reward variant ``name`` (:data:`VARIANTS`), built on ``base``'s
    knobs."""
    if name not in VARIANTS:
        raise ValueError(f"unknown reward variant {name!r}; expected one of {', '.join(VARIANTS)}")
    chosen = VARIANTS[name]
    weights = reward_form(chosen.reward, base)
    return weights if chosen.imitation else dataclasses.replace(weights, imitation=False)


@struct.dataclass
class RewardParams:
    """Everything the reward of one demonstration needs; all leaves are arrays.

    Shapes are for one demonstration; a stacked pytree (:func:`stack_params`) adds a
    leading ``n_demos`` axis to every leaf. ``L`` is the common reference length.
    Offsets are expressed in the frame of target body ``j_min`` (palm body for
    ``j_min = 0``, the finger's distal body otherwise); points are ``HAND_POINTS`` rows.
    """

    j_min: jax.Array  # () int32: target point (HAND_POINTS row) of the closest approach
    d_min: jax.Array  # () float32: closest fingertip-to-target-point distance, metres
    t_min_frame: jax.Array  # () int32: capture frame of the closest approach (in the window)
    t_min_step: jax.Array  # () int32: control step of t_min (last step at or before it)
    imitation_length: jax.Array  # () int32: t_min_step + 1, valid rows of the references
    contact_begin_step: jax.Array  # () int32: control step of demo.contact_begin
    contact_end_step: jax.Array  # () int32: control step of demo.contact_end
    goal_offsets: jax.Array  # (6, 3): Δp of the 6 actor points at t_min, body j_min frame
    goal_angles: jax.Array  # (20,): actor joint angles at t_min, HAND_JOINTS order
    ref_offsets: jax.Array  # (L, 6, 3): Δp per control step; rows >= imitation_length = t_min
    ref_angles: jax.Array  # (L, 20): actor joint angles per control step
    ref_palm_pos: jax.Array  # (L, 3): actor palm centre in the target palm frame
    ref_palm_rot: jax.Array  # (L, 3, 3): actor palm orientation in the target palm frame
    ref_target_joints: jax.Array  # (L, 20): target hand joint angles per control step
    w_position: jax.Array  # (6,): ω_p, zero for actor points the variant does not reward
    w_angle: jax.Array  # (20,): ω_α
    w_contact: jax.Array  # (15,): ω_c, > 0 required, < 0 forbidden, 0 elsewhere / no contacts
    contact_bias: jax.Array  # (): b_c, -Σ of the required ω_c in the penalty form, else 0
    w_action: jax.Array  # (24,): ω_a over ARM_JOINTS + HAND_JOINTS controls
    w_imitation_position: jax.Array  # (6,): ω_pI, 0 when imitation is off
    w_imitation_angle: jax.Array  # (20,): ω_αI, 0 when imitation is off
    required_contacts: jax.Array  # (15,) bool: sensors the contact term rewards
    success_groups: jax.Array  # (N_GROUPS, 15) bool: one sensor of each must touch


@struct.dataclass
class VariantWeights:
    """The leaves of :class:`RewardParams` that a reward variant sets, for every demo.

    Everything else in the parameters (goals, references, required contacts) is the
    same for all variants, so a variant is just these arrays: runs of an experiment
    grid that differ in their reward differ in data, not in the compiled program.
    Shapes carry the leading ``n_demos`` axis of a stacked ``RewardParams``.
    """

    w_position: jax.Array  # (n_demos, 6)
    w_angle: jax.Array  # (n_demos, 20)
    w_contact: jax.Array  # (n_demos, 15)
    contact_bias: jax.Array  # (n_demos,)
    w_action: jax.Array  # (n_demos, 24)
    w_imitation_position: jax.Array  # (n_demos, 6)
    w_imitation_angle: jax.Array  # (n_demos, 20)


VARIANT_FIELDS = tuple(f.name for f in dataclasses.fields(VariantWeights))


def variant_weights(params: RewardParams) -> VariantWeights:
    """The variant's leaves of ``params`` (stacked or single-demo)."""
    return VariantWeights(**{name: getattr(params, name) for name in VARIANT_FIELDS})


def with_variant(params: RewardParams, weights: VariantWeights) -> RewardParams:
    """``params`` with the reward variant ``weights`` (same demo axes as ``params``)."""
    return params.replace(**{name: getattr(weights, name) for name in VARIANT_FIELDS})


def _check_demo(demo: Demonstration) -> None:
    """Raise ValueError if ``demo`` cannot feed Algorithm 1."""
    name = getattr(demo, "name", "?")
    if demo.task not in REQUIRED_CONTACTS:
        raise ValueError(
            f"{name}: unknown task {demo.task!r}; expected one of {', '.join(REQUIRED_CONTACTS)}"
        )
    if not (np.isfinite(demo.fps) and demo.fps > 0):
        raise ValueError(f"{name}: fps must be a positive number, got {demo.fps!r}")
    n = len(demo.actor_joints)
    shapes = {
        "actor_joints": (n, N_JOINTS),
        "target_joints": (n, N_JOINTS),
        "actor_points": (n, N_POINTS, 3),
        "actor_palm_rot": (n, 3, 3),
        "target_points": (n, N_POINTS, 3),
        "target_frames": (n, N_POINTS, 3, 3),
    }
    for field, shape in shapes.items():
        got = np.shape(getattr(demo, field))
        if got != shape:
            raise ValueError(f"{name}: {field} has shape {got}, expected {shape} (T = {n})")
    if not 0 <= demo.contact_begin <= demo.contact_end:
        raise ValueError(
            f"{name}: need 0 <= contact_begin <= contact_end, got "
            f"{demo.contact_begin}, {demo.contact_end}"
        )
    if demo.contact_end > n - 1:
        raise ValueError(
            f"{name}: contact_end = {demo.contact_end} is beyond the data (T = {n} frames)"
        )
    for field in shapes:
        if not np.all(np.isfinite(np.asarray(getattr(demo, field))[: demo.contact_end + 1])):
            raise ValueError(f"{name}: {field} has non-finite values in frames 0..contact_end")


def _offsets(demo: Demonstration, j: int) -> np.ndarray:
    """(T, 6, 3): actor points relative to target point ``j``, in target body j's frame."""
    rel = np.asarray(demo.actor_points, np.float64) - np.asarray(demo.target_points)[:, j, None]
    return np.einsum("tba,tib->tia", np.asarray(demo.target_frames, np.float64)[:, j], rel)


def closest_approach(demo: Demonstration) -> tuple[int, int, int, float]:
    """Steps 1-2 of Algorithm 1: ``(t_min, i_min, j_min, d_min)``.

    ``i_min`` is the actor fingertip as a ``HAND_POINTS`` row (1..5), ``j_min`` the target
    ``HAND_POINTS`` row, ``t_min`` a frame in ``[contact_begin, contact_end]``; ties go to the
    earliest frame, then the lowest rows.
    """
    _check_demo(demo)
    window = slice(demo.contact_begin, demo.contact_end + 1)
    tips = np.asarray(demo.actor_points, np.float64)[window, _TIPS]  # (t, 5, 3)
    targets = np.asarray(demo.target_points, np.float64)[window]  # (t, 6, 3)
    d = np.linalg.norm(tips[:, :, None] - targets[:, None], axis=-1)  # (t, 5, 6)
    t, i, j = np.unravel_index(np.argmin(d), d.shape)
    return int(t) + demo.contact_begin, int(i) + 1, int(j), float(d[t, i, j])


def frames_per_step(demo: Demonstration, dt: float) -> float:
    """Capture frames per control step, ``fps·dt``."""
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
    return float(demo.fps) * dt


def step_of_frame(frame: int, frames_per_step: float) -> int:
    """The last control step at or before capture frame ``frame``."""
    # The epsilon keeps exact multiples (e.g. 24 / 4.8) from rounding down a step.
    return int(np.floor(frame / frames_per_step + 1e-9))


def imitation_length(demo: Demonstration, dt: float = CONTROL_DT) -> int:
    """Number of control steps from the window's start up to and including ``t_min``."""
    return step_of_frame(closest_approach(demo)[0], frames_per_step(demo, dt)) + 1


def resample(x: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``x`` (T, ...) at fractional ``frames`` (K,) -> (K, ...)."""
    lo = np.floor(frames).astype(int)
    hi = np.minimum(lo + 1, len(x) - 1)
    s = (frames - lo).reshape((-1,) + (1,) * (x.ndim - 1))
    return (1 - s) * x[lo] + s * x[hi]


def nearest_rotation(m: np.ndarray) -> np.ndarray:
    """Project (..., 3, 3) matrices onto SO(3): interpolated rotations are not rotations."""
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt))
    u = u.copy()
    u[..., :, -1] *= d[..., None]
    return u @ vt


def algorithm1(
    demo: Demonstration,
    weights: RewardWeights = RewardWeights(),
    dt: float = CONTROL_DT,
    length: int | None = None,
) -> RewardParams:
    """Reward parameters of one demonstration (NumPy leaves, float32 / int32 / bool).

    Args:
      demo: the demonstration, frames ``0..T-1`` of its window.
      weights: knobs and variant switches.
      dt: control period, seconds.
      length: rows ``L`` of the per-step references; default ``imitation_length``.
        Rows past ``t_min_step`` hold the values at frame ``t_min`` (padding).
    """
    t_min, _, j_min, d_min = closest_approach(demo)
    r = frames_per_step(demo, dt)
    t_min_step = step_of_frame(t_min, r)
    n_valid = t_min_step + 1
    length = n_valid if length is None else int(length)
    if length < n_valid:
        raise ValueError(
            f"{demo.name}: length {length} is shorter than the imitation length {n_valid}"
        )

    offsets = _offsets(demo, j_min)  # (T, 6, 3)
    frames = np.minimum(np.arange(length) * r, t_min)  # clamping pads with the t_min value

    d_goal = np.linalg.norm(offsets[t_min], axis=-1)  # (6,) = d^{i j_min}_{t_min}
    if weights.position_points == "fingertips":
        selected = np.arange(1, N_POINTS)
    else:
        selected = np.array([0])
    # Normalise by the closest *selected* point: d_min for fingertips, the palm itself
    # for Baseline 1, so that the rewarded point nearest to the target weighs K_p.
    floored = np.maximum(d_goal, DISTANCE_FLOOR)
    point_shape = np.zeros(N_POINTS)  # Algorithm 1's ratios, the closest selected point 1
    point_shape[selected] = floored[selected].min() / floored[selected]
    w_position = weights.K_p * point_shape
    on = 1.0 if weights.imitation else 0.0
    if weights.imitation_weights == "relative":
        w_imitation_position = on * weights.K_pI * w_position
        w_imitation_angle = np.full(N_JOINTS, on * weights.K_alphaI * weights.K_alpha)
    else:
        w_imitation_position = on * weights.K_pI * point_shape
        w_imitation_angle = np.full(N_JOINTS, on * weights.K_alphaI)

    required = required_contact_mask(demo.task)
    forbidden = np.zeros(N_SENSORS, bool)
    forbidden[[shadow_hand.sensor_index(n) for n in weights.forbidden_contacts]] = True
    k_c = weights.K_c if weights.contact else 0.0
    w_contact = k_c * (required.astype(np.float64) - forbidden)
    contact_bias = -k_c * required.sum() if weights.contact_form == "penalty" else 0.0
    f32 = lambda x: np.asarray(x, np.float32)
    i32 = lambda x: np.asarray(x, np.int32)
    return RewardParams(
        j_min=i32(j_min),
        d_min=f32(d_min),
        t_min_frame=i32(t_min),
        t_min_step=i32(t_min_step),
        imitation_length=i32(n_valid),
        contact_begin_step=i32(step_of_frame(demo.contact_begin, r)),
        contact_end_step=i32(step_of_frame(demo.contact_end, r)),
        goal_offsets=f32(offsets[t_min]),
        goal_angles=f32(demo.actor_joints[t_min]),
        ref_offsets=f32(resample(offsets, frames)),
        ref_angles=f32(resample(np.asarray(demo.actor_joints, np.float64), frames)),
        ref_palm_pos=f32(resample(np.asarray(demo.actor_points, np.float64)[:, 0], frames)),
        ref_palm_rot=f32(
            nearest_rotation(resample(np.asarray(demo.actor_palm_rot, np.float64), frames))
        ),
        ref_target_joints=f32(resample(np.asarray(demo.target_joints, np.float64), frames)),
        w_position=f32(w_position),
        w_angle=f32(np.full(N_JOINTS, weights.K_alpha)),
        w_contact=f32(w_contact),
        contact_bias=f32(contact_bias),
        w_action=f32(np.full(N_CONTROLS, weights.K_a)),
        w_imitation_position=f32(w_imitation_position),
        w_imitation_angle=f32(w_imitation_angle),
        required_contacts=required,
        success_groups=success_group_mask(demo.task),
    )


def stack_params(params: Sequence[RewardParams]) -> RewardParams:
    """Stack single-demo params into one pytree with a leading ``n_demos`` axis.

    All must share the reference length ``L``: build them with a common ``length``
    (as :func:`build_task_params` does).
    """
    params = list(params)
    if not params:
        raise ValueError("stack_params needs at least one RewardParams")
    lengths = {np.shape(p.ref_angles)[0] for p in params}
    if len(lengths) > 1:
        raise ValueError(
            f"reference lengths differ ({sorted(lengths)}); pass a common `length` to "
            "algorithm1 or use build_task_params"
        )
    return jax.tree.map(lambda *xs: np.stack(xs), *params)


def build_task_params(
    demos: Sequence[Demonstration],
    weights: RewardWeights = RewardWeights(),
    dt: float = CONTROL_DT,
) -> RewardParams:
    """Algorithm 1 for every demonstration of one task, stacked, as ``jax.Array`` leaves.

    Select demo ``i`` inside jit with ``jax.tree.map(lambda x: x[i], params)``.
    """
    demos = list(demos)
    if not demos:
        raise ValueError("build_task_params needs at least one demonstration")
    tasks = sorted({d.task for d in demos})
    if len(tasks) > 1:
        raise ValueError(f"demonstrations of one task expected, got tasks {tasks}")
    length = max(imitation_length(d, dt) for d in demos)
    stacked = stack_params([algorithm1(d, weights, dt, length) for d in demos])
    return jax.tree.map(jnp.asarray, stacked)

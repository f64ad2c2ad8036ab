"""The configuration of a hand-interaction environment (:class:`EnvConfig`), its checks
and the reward weights it asks for.

A light module (no MJX, no compiled programs): the training config holds an
``EnvConfig`` as its ``env`` field, so the command line's ``--task``, ``--profile``,
``--knobs.*``, partner options ... are this dataclass's fields
(:mod:`mjx_hands.train_config`); :class:`mjx_hands.env.HandInteractionEnv` is built from
it.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np

from mjx_hands import profiles, reward_params, scene, tasks
from mjx_hands.partner import DEFAULT_SHARE

Task = Literal[tasks.TASKS]  # the registry's names, as choices of --task
DEMO_SETS = ("authors", "all")
"""``EnvConfig.demos``: the demonstrations the authors trained on, or all recorded."""
MOCAP_SOURCES = ("auto", "optitrack", "synthetic")
PHYSICS = ("auto", "mjx", "native", "warp")
"""``EnvConfig.physics``: MJX, native C MuJoCo, MuJoCo Warp, or auto (native on CPUs, MJX
elsewhere); ``mjx_hands.physics``."""
PARTNERS = ("static", "recorded")
PARTNER_MOTIONS = ("per_step", "continuous")
"""``EnvConfig.partner_motion``: how a moving partner's kinematic hand travels within a
control period."""
"""``EnvConfig.partner``: a target hand that holds one pose, or one that replays its
demonstration (``mjx_hands.partner``)."""


def reward_weights(config: EnvConfig) -> reward_params.RewardWeights:
    """The reward weights ``config`` asks for: its profile's weights of its task's
    variant (``reward``, ``imitation``), ``knobs`` set over them. The one place knobs
    become weights: the environment, a training config's checks and its config.json all
    read this."""
    return profiles.reward_weights(
        config.profile, config.task, config.reward, config.imitation, config.knobs
    )


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """Everything that defines an environment instance (all static under jit)."""

    task: Task = "handshake"
    """Interaction to learn (a name in ``mjx_hands.tasks``)."""
    profile: profiles.Profile = "project"
    """'project' (the project's observation, contact rule, weights and target box;
    training with ``ddpg-ln`` by default) or 'paper' (the authors' environment: their
    observation, touch sensors, per-task and per-variant weights, reward <= 0 with the
    critic target clipped to [-T, 0], target boxes, and their DDPG's replay ratio, buffer
    and 50-epoch budget). See ``mjx_hands.profiles``."""
    reward: Literal[tuple(reward_params.REWARD_FORMS)] = "full"
    """Reward form (``reward_params.REWARD_FORMS``): 'full', 'baseline1' (palm position),
    'baseline2' (no contact); with ``imitation`` it makes one of the named
    ``reward_params.VARIANTS``."""
    imitation: bool = True
    """Imitation terms r_pI, r_αI on top of the variant (False: any variant without them)."""
    knobs: reward_params.RewardKnobs = reward_params.RewardKnobs()
    """The reward's six knobs (``--knobs.K-p 4`` ...); unset ones take the task's own
    (``tasks.TaskSpec.reward_knobs``: the handshake the authors' K_p 4, K_c 0.5, K_alpha
    0; the clap and E.T. K_p 1, K_c 0.2, K_alpha 0.1). A run's config.json records every
    value. Under ``profile='paper'`` unset knobs take the authors' config of each
    variant, and set ones override every variant's."""
    mocap_source: Literal[MOCAP_SOURCES] = "auto"
    """Which demonstrations to read: 'optitrack' (the authors' recordings), 'synthetic'
    (the project's mocap_data/) or 'auto' (the recordings when present)."""
    mocap: str | None = None
    """Folder of the demonstrations; None: the source's default location
    (../shared/mocap/drl_handshake, or the project's mocap_data/)."""
    demos: Literal[DEMO_SETS] = "authors"
    """Which of the recordings' demonstrations: 'authors' (those the authors trained on,
    ``tasks.TaskSpec.authors_demos``) or 'all'. The project's synthetic files are used
    whole."""
    control_dt: float = tasks.CONTROL_DT
    """Control period, seconds (a multiple of the physics timestep)."""
    episode_length: int | None = None
    """Control steps per episode; None takes the paper's (100 handshake, 75 otherwise)."""
    contact_point: tuple[float, float, float] = (0.45, 0.0, 0.0)
    """Where the agent's palm centre is at the demonstrated contact when the target is
    at its nominal pose (world, metres; the shoulder is at the origin)."""
    target_box: tuple[float, float, float] = (0.05, 0.05, 0.05)
    """Half-extent of the uniform box of target palm positions, metres (the project
    profile's; the paper profile draws from the authors' per-task boxes)."""
    target_rotation_noise: float = 0.0
    """Std of the angle (radians) of a random rotation, about a uniformly random axis,
    applied to the target hand per episode (0: the task's nominal orientation; the
    paper's robustness experiments perturb it)."""
    target_rotation_angle: float | None = None
    """If set, every episode's target hand is turned by exactly this angle (radians)
    about a uniformly random axis instead."""
    target_orientation_range: tuple[float, float, float] | None = None
    """Partner model "orientation": half-ranges (radians) of the target hand's yaw, pitch
    and roll, each drawn uniformly per episode and applied about its palm centre as
    :func:`yaw_pitch_roll_quat` (yaw about the vertical, pitch about the horizontal axis
    across the agent's view, roll about the agent's line of sight); goals turn with it.
    None: the tilt of ``target_rotation_noise`` / ``target_rotation_angle``."""
    target_speed: float | None = None
    """None: the target hand stays where reset put it (the paper's training). A number
    (m/s): it moves at this speed in a uniformly random direction, drawn anew every
    ``target_turn_period`` seconds and mirrored at the walls of ``target_motion_box``;
    goals and imitation references move with it (the paper's moving-target test,
    ``mjx_hands.robustness``). ``reset_with`` can set the speed per episode."""
    target_speed_range: tuple[float, float] | None = None
    """Partner model "motion": each episode's speed drawn uniformly from [low, high] m/s
    (the target moves as with ``target_speed``, which it replaces); None: ``target_speed``."""
    target_position_noise: float = 0.0
    """Partner model "sensing": std (metres) of a Gaussian error of the observed target
    position, drawn anew every control step, as a motion-capture or vision estimate of
    the partner's hand would carry: everything the observation says about the target
    (its points or links, the goals and imitation references that follow it) moves by
    the same error; the physics and the reward see the true hand. 0: exact."""
    action_delay: int = 0
    """Partner model "actuation": control steps between a policy's action and the
    actuators receiving it (a robot controller's latency); the first steps of an episode
    apply the action that holds the start pose. The reward's action term charges the
    policy's own action. 0: none."""
    action_delay_range: tuple[int, int] | None = None
    """Partner model "actuation" drawn per episode: the delay (control steps) uniformly
    from the whole numbers [low, high], replacing ``action_delay`` (give one), so that
    a policy trained with it meets every latency of a controller it may run on. None:
    ``action_delay``. A policy without memory cannot tell which of its actions still
    wait: train it with ``observe_recent_actions`` >= high."""
    observe_recent_actions: int = 0
    """Observe the policy's own last K actions too (24 each, most recent first; the
    start pose's holding action before the first step; the project observation only).
    With an action delay of d <= K steps they hold every action still waiting for the
    actuators, which makes the delayed problem Markov again (the augmented state of a
    delayed MDP). Part of the observation, not a partner model: both stages of a
    curriculum must agree on it. 0: none."""
    observe_target_velocity: bool = False
    """Observe the partner's palm velocity too (m/s, world axes; the project observation
    only): the difference of its last two observed positions over the control period,
    as a tracker would estimate it, so it carries the sensing error's difference
    (sqrt(2) x noise / period per axis: 0.07 m/s at 2 mm); zeros at an episode's first
    step. A policy without memory sees only where a moving partner
    was; this tells it where the partner is going. Part of the observation, not a partner
    model: both stages of a curriculum must agree on it."""
    action_rate_weight: float = 0.0
    """Weight w of a smoothness term added to the reward, ``-w Σ_i (a_i,t - a_i,t-1)²``
    over the 24 controls (the first step's previous action: the one that holds the start
    pose), logged as ``reward/action_rate``. Not one of the paper's six terms: robust
    stages trade smoothness for contact (palm jerk +50 % on the clap) and this charges
    it. Unless ``observe_recent_actions`` shows it, the previous action is not observed,
    so the term is only partly predictable from the observation (the joints lag their
    set-points: their positions and velocities carry part of it). 0: none (the paper's
    reward)."""
    partner: Literal[PARTNERS] = "static"
    """Partner model "recorded partner": 'static' (the paper's: the target hand holds one
    pose of its demonstration, drawn per episode between the agent's start and the
    closest approach) or 'recorded' (it replays the demonstration's own approach: its
    palm travels and turns along its recorded path, which ends at the placed pose at the
    closest approach, and its fingers move through their recorded angles, closing at
    contact; then it holds the window's last frame). Goals and imitation references
    follow it. See ``mjx_hands.partner``."""
    partner_model_probability: float = 1.0
    """Per episode, each of the partner models orientation (``target_orientation_range``),
    motion (``target_speed_range``) and recorded partner (``partner = 'recorded'``)
    applies with this probability, independently; an episode it skips has that model's
    static counterpart (the nominal orientation, a still target, the paper's static
    hand). Sensing error and action delay always apply. 1: every model in every episode;
    below 1 a robust stage keeps practising each condition alone and the static one,
    as it is scored (``mjx_hands.robustness`` changes one condition at a time)."""
    partner_share: float = DEFAULT_SHARE
    """The recorded partner's share of the palms' closing where the recordings hold only
    the palm-to-palm vector (the authors' release; imported takes record the path)."""
    partner_lag: tuple[int, int] = (-5, 5)
    """[low, high] control steps, drawn uniformly per episode: how far the recorded
    partner runs ahead of (> 0) or behind (< 0) the demonstration's time at the agent's
    start, so that its arrival is not tied to the agent's start."""
    partner_motion: Literal[PARTNER_MOTIONS] = "per_step"
    """How the partner hand (kinematic: mocap bodies) travels within a control period,
    wherever it moves (``target_speed``, the recorded partner): 'per_step' places it at
    the period's pose before the period's physics substeps, a jump of speed x
    ``control_dt`` (8 mm at 0.2 m/s) into or away from the agent's fingers; 'continuous'
    carries it from the last period's pose to this one's in equal parts over the
    substeps (positions linearly, orientations by normalised linear interpolation), as a
    human hand moves. Both reach the same poses at the ends of the periods."""
    target_turn_period: float = 0.5
    """Seconds between the moving target's changes of direction."""
    target_motion_box: tuple[float, float, float] = (0.1, 0.1, 0.1)
    """Half-extent (metres) of the box around the nominal target palm position that the
    moving target stays in (within the arm's reach)."""
    start_offset_steps: int = 5
    """t_off: the latest start step is t_min - t_off (control steps)."""
    start_position_noise: float = 0.02
    """Std of the Gaussian noise on the starting palm position, metres."""
    start_joint_noise: float = 0.05
    """Std of the Gaussian noise on the starting finger angles, radians."""
    contact_distance: float = 0.002
    """A sensor reads 1 when one of its geoms is closer than this to the target, metres."""
    start_max_penetration: float = 0.001
    """Deepest agent-target interpenetration (metres) a start may have; a deeper one
    starts earlier in the demonstration (see ``HandInteractionEnv._separated_start``)."""
    start_backoff_steps: int = 5
    """Control steps each retreat moves the start earlier."""
    start_backoff_distance: float = 0.02
    """Metres each retreat at the demonstration's first step moves the palm away from
    the target's, along the line between the palm centres (0: stop at step 1)."""
    start_retreats: int = 8
    """Most retreats per start; 0 keeps every drawn start as it is (the paper's)."""
    ik_iterations: int = 30
    """Damped least-squares iterations placing the arm at the start pose."""
    physics: Literal[PHYSICS] = "auto"
    """Physics implementation: 'mjx' (MJX, accelerators), 'native' (C MuJoCo on every
    CPU core, called from the compiled program), 'warp' (MuJoCo Warp through MJX; GPUs,
    or Warp's CPU device; needs the ``[warp]`` extra) or 'auto' (native on CPUs, MJX
    elsewhere); see ``mjx_hands.physics``."""
    scene: scene.SceneConfig = scene.SceneConfig()
    """Physics settings."""

    def __post_init__(self):
        problems = config_problems(self)
        if problems:
            raise ValueError("EnvConfig: " + "; ".join(problems))


PARTNER_SETUPS = ("static", "robust", "mixed")
"""Named sets of partner models to train with (``--partners``): the paper's static target,
:data:`ROBUST_PARTNERS` (every model in every episode) or :data:`MIXED_PARTNERS` (each
model in half the episodes)."""
ROBUST_PARTNERS = {
    "partner": "recorded",
    # A margin past the +-30 deg yaw x pitch the robust policy is held to; roll +-10 deg.
    "target_orientation_range": (0.61, 0.61, 0.17),
    # Still to past the 0.2 m/s it is held to, uniformly per episode.
    "target_speed_range": (0.0, 0.25),
    # Motion capture / vision error of the partner's hand position.
    "target_position_noise": 0.002,
}
"""The robust setup's partner models: a recorded partner that arrives as the human did,
turned per episode, carried along at a random speed, observed with 2 mm noise."""


MIXED_PARTNERS = ROBUST_PARTNERS | {"partner_model_probability": 0.5}
"""The robust setup's models, each drawn on in half the episodes (independently): an
eighth of the episodes meet the static partner, three eighths one model alone."""


def with_partners(config: EnvConfig, setup: str) -> EnvConfig:
    """``config`` against the partner models of ``setup`` (``PARTNER_SETUPS``), every
    partner field set: 'static' the paper's static partner (:func:`static_partner`),
    'robust' :data:`ROBUST_PARTNERS` and 'mixed' :data:`MIXED_PARTNERS` over it. Flags
    parsed afterwards override fields."""
    if setup not in PARTNER_SETUPS:
        raise ValueError(f"unknown partners {setup!r}; expected one of {', '.join(PARTNER_SETUPS)}")
    static = static_partner(config)
    models = {"static": {}, "robust": ROBUST_PARTNERS, "mixed": MIXED_PARTNERS}[setup]
    return dataclasses.replace(static, **models)


STATIC_PARTNER = {
    "partner": "static",
    "target_rotation_noise": 0.0,
    "target_rotation_angle": None,
    "target_orientation_range": None,
    "target_speed": None,
    "target_speed_range": None,
    "target_position_noise": 0.0,
    "action_delay": 0,
    "action_delay_range": None,
    "partner_model_probability": 1.0,
    "action_rate_weight": 0.0,
}
"""The paper's partner: a static hand at its nominal orientation, seen exactly, with
actions applied at once; and the paper's reward, without the smoothness term a robust
stage may add (success is what scoring compares; one scoring env for every policy)."""


def partner_models(config: EnvConfig) -> dict[str, object]:
    """The partner models ``config`` trains or scores against (the fields of
    :data:`STATIC_PARTNER`)."""
    return {name: getattr(config, name) for name in STATIC_PARTNER}


def static_partner(config: EnvConfig) -> EnvConfig:
    """``config`` with :data:`STATIC_PARTNER`: the conditions in which every policy of a
    task is scored alike, whatever partner models it trained against (evaluation sweeps
    then change one condition at a time)."""
    return dataclasses.replace(config, **STATIC_PARTNER)


def moving(config: EnvConfig) -> bool:
    """Whether ``config``'s target hand moves (``target_speed`` or ``target_speed_range``)."""
    return config.target_speed is not None or config.target_speed_range is not None


def config_problems(config: EnvConfig) -> list[str]:
    """What is wrong with ``config`` (empty: nothing), each naming the field and what it
    expects: names outside their vocabularies, and a target orientation or motion that
    cannot be simulated as configured."""
    problems = [
        f"unknown {name} {getattr(config, name)!r}; expected one of {', '.join(choices)}"
        for name, choices in (
            ("task", tasks.TASKS),
            ("profile", profiles.PROFILES),
            ("reward", tuple(reward_params.REWARD_FORMS)),
            ("mocap_source", MOCAP_SOURCES),
            ("demos", DEMO_SETS),
            ("physics", PHYSICS),
            ("partner", PARTNERS),
            ("partner_motion", PARTNER_MOTIONS),
        )
        if getattr(config, name) not in choices
    ]
    if not isinstance(config.knobs, reward_params.RewardKnobs):
        problems.append(f"knobs must be a RewardKnobs, got {type(config.knobs).__name__}")
    ranges = config.target_orientation_range
    if ranges is not None:
        if len(ranges) != 3 or not all(np.isfinite(h) and 0 <= h <= np.pi for h in ranges):
            problems.append(
                f"target_orientation_range {ranges} must be three half-ranges in [0, pi] "
                "radians (yaw, pitch, roll)"
            )
        if config.target_rotation_noise or config.target_rotation_angle is not None:
            problems.append(
                "target_orientation_range and target_rotation_noise/target_rotation_angle "
                "both turn the target: give one"
            )
    if (
        config.observe_target_velocity
        and profiles.env_profile(config.profile).observation == "paper"
    ):
        problems.append(
            "observe_target_velocity needs the project observation; the paper profile's is "
            "the authors' (no velocity of the partner)"
        )
    if not (np.isfinite(config.action_rate_weight) and config.action_rate_weight >= 0):
        problems.append(f"action_rate_weight {config.action_rate_weight} must be >= 0")
    if not (isinstance(config.action_delay, int) and config.action_delay >= 0):
        problems.append(f"action_delay {config.action_delay!r} must be a whole number >= 0")
    delays = config.action_delay_range
    if delays is not None:
        if not (
            len(delays) == 2
            and all(isinstance(v, int) and v >= 0 for v in delays)
            and delays[0] <= delays[1]
        ):
            problems.append(
                f"action_delay_range {delays} must be [low, high] whole control steps, "
                "0 <= low <= high"
            )
        if config.action_delay:
            problems.append("action_delay and action_delay_range both delay actions: give one")
    recent = config.observe_recent_actions
    if not (isinstance(recent, int) and recent >= 0):
        problems.append(f"observe_recent_actions {recent!r} must be a whole number >= 0")
    elif recent and profiles.env_profile(config.profile).observation == "paper":
        problems.append(
            "observe_recent_actions needs the project observation; the paper profile's is "
            "the authors' (no actions)"
        )
    probability = config.partner_model_probability
    if not (np.isfinite(probability) and 0 <= probability <= 1):
        problems.append(f"partner_model_probability {probability} must be in [0, 1]")
    if not (np.isfinite(config.partner_share) and 0 <= config.partner_share <= 1):
        problems.append(f"partner_share {config.partner_share} must be in [0, 1]")
    lag = config.partner_lag
    if not (len(lag) == 2 and all(isinstance(v, int) for v in lag) and lag[0] <= lag[1]):
        problems.append(f"partner_lag {lag} must be [low, high] whole control steps, low <= high")
    for name in ("target_rotation_noise", "target_position_noise"):
        value = getattr(config, name)
        if not (np.isfinite(value) and value >= 0):
            problems.append(f"{name} {value} must be a finite number >= 0")
    if not moving(config):
        return problems
    if config.target_speed is not None and not (
        np.isfinite(config.target_speed) and config.target_speed >= 0
    ):
        problems.append(f"target_speed {config.target_speed} must be >= 0 m/s (None: static)")
    speeds = config.target_speed_range
    if speeds is not None and not (
        len(speeds) == 2 and all(np.isfinite(v) for v in speeds) and 0 <= speeds[0] <= speeds[1]
    ):
        problems.append(
            f"target_speed_range {speeds} must be [low, high] m/s with 0 <= low <= high"
        )
    if not (np.isfinite(config.target_turn_period) and config.target_turn_period > 0):
        problems.append(f"target_turn_period {config.target_turn_period} must be positive")
    if not all(np.isfinite(b) and b > 0 for b in config.target_motion_box):
        problems.append(f"target_motion_box {config.target_motion_box} must be positive metres")
    return problems

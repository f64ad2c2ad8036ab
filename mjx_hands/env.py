"""The hand-interaction environment: Brax ``Env`` API over the MJX hand-pair scene.

``reset(rng) -> State`` and ``step(State, action) -> State`` are pure and act on a
single environment; :func:`make_env` returns it wrapped so that both take and
return a batch (``jax.vmap``) and finished episodes restart with fresh
randomisation (see :class:`BatchedEnv`).

Episode randomisation (the paper's training method):

* a demonstration of the task, uniformly at random;
* the target palm position uniformly in a box around its nominal position; the
  target's orientation is the task's nominal one (both from :func:`place_target`);
* the target's finger angles from the demonstration at a control step drawn
  uniformly between the start step (as drawn, below) and ``t_min``;
* the start step ``t_s`` uniformly in ``[1, t_min - t_off]``: the agent's palm is
  put at the actor's palm pose of that step (plus Gaussian noise) by inverse
  kinematics of the arm and wrist, the fingers at the actor's angles (plus noise),
  and the imitation reference runs from there. A start whose hands interpenetrate
  (robot arm and Shadow hand are not the human's: IK misses, fingers overlap) moves
  earlier along the same demonstration until they are apart; at step 1 the palm
  backs away from the target's along the line between the palm centres instead, at
  most ``start_retreats`` moves in all (``_separated_start``).

Observation (``observation_size`` = 145, + 3 with ``observe_target_velocity``, + 24 K with
``observe_recent_actions`` = K), in this order:

====================  ====  ================================================
agent qpos            28    arm (4) + hand joints (24), radians
agent qvel            28    scaled by 0.1
contacts              15    ``CONTACT_SENSORS`` readings, 0/1
agent points          18    palm + fingertips minus target palm centre (world axes)
goal offset           18    goal minus current point, per hand point
imitation offset      18    imitation reference minus current point (0 past t_min)
target points         18    target palm + fingertips minus agent palm centre
phase                  2    step / episode length, imitation-active flag
target velocity        3    with ``observe_target_velocity`` only: the partner's
                            palm, m/s, world axes, from its observed positions
recent actions       24 K   with ``observe_recent_actions`` = K only: the policy's
                            last K actions in [-1, 1], most recent first
====================  ====  ================================================

That is the project profile's. The paper profile (``EnvConfig.profile = "paper"``,
``mjx_hands.profiles``) observes what the authors' environment does (134): agent qpos
(28), qvel x control period (28), the target hand's 21 link positions in the world (63)
and the 15 touch sensors (0/1); it draws the target from the authors' per-task boxes
and reads contact from touch sensors.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from brax.envs.base import Env, State, Wrapper
from flax import struct

from mjx_hands import (
    ik,
    mocap,
    partner,
    physics,
    profiles,
    reward_params,
    rewards,
    scene,
    spatial,
    tasks,
)
from mjx_hands import shadow_hand as sh
from mjx_hands.contract import InteractionEnv
from mjx_hands.env_config import DEMO_SETS, EnvConfig, moving, reward_weights, static_partner

TASKS = tasks.TASKS


# IK starting posture (arm joints, then WRJ1, WRJ0): elbow bent, away from the
# stretched-arm singularity where reaching closer to the shoulder has no gradient.
IK_SEED = np.array([0.0, 0.0, 0.0, 1.2, 0.0, 0.0], np.float32)


def place_target(
    params: reward_params.RewardParams, task: str, contact_point: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World pose of the target palm that puts the demonstrated contact in front of the agent.

    The demonstrations say where the actor's palm is relative to the target palm at
    the closest approach t_min. Averaged over the task's demonstrations, that pose is
    mapped onto a comfortable agent palm pose (the task's ``contact_rotation`` at
    ``contact_point``); the inverse of that map places the target.

    Returns:
      position (3,) of the target palm centre and rotation (3, 3), world.
    """
    t_min = np.asarray(params.t_min_step)
    demos = np.arange(t_min.shape[0])
    actor_rot = np.asarray(params.ref_palm_rot)[demos, t_min].mean(axis=0)
    u, _, vt = np.linalg.svd(actor_rot)  # chordal mean: nearest rotation to the average
    actor_rot = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    actor_pos = np.asarray(params.ref_palm_pos)[demos, t_min].mean(axis=0)
    rot = tasks.spec(task).contact_rotation_matrix @ actor_rot.T
    return np.asarray(contact_point) - rot @ actor_pos, rot


SENSING_KEY = 0x5E45
"""Folded into an episode's key for its sensing errors (``EnvConfig.target_position_noise``)."""
PAPER_UNOBSERVED_LINKS = ("forearm", "lfmetacarpal")


def select_demos(demos: list, task: str, which: str) -> list:
    """``demos`` of the recordings restricted to ``which`` set (see ``EnvConfig.demos``).

    The authors left out, e.g., handshake rows 3-6, whose ``interaction_t`` window lies
    in the approach, 4-5 cm short of the grip (``benchmarks/results/fidelity.md``).
    """
    if which not in DEMO_SETS:
        raise ValueError(f"unknown demonstration set {which!r}; expected one of {DEMO_SETS}")
    if which == "all" or demos[0].source != "optitrack":
        return demos
    by_row = {int(d.name.rsplit("/", 1)[-1]): d for d in demos}
    rows = tasks.spec(task).authors_demos
    missing = [r for r in rows if r not in by_row]
    if missing:
        raise ValueError(
            f"{task}: the recordings lack rows {missing} of the authors' set {rows}; "
            "pass demos='all' to use what there is"
        )
    return [by_row[r] for r in rows]


def random_direction(rng: jax.Array) -> jax.Array:
    """A unit vector (3,) uniformly distributed on the sphere."""
    v = jax.random.normal(rng, (3,))
    return v / jnp.maximum(jnp.linalg.norm(v), 1e-9)


def target_tilt(rng: jax.Array, noise: float, angle: float | None = None) -> jax.Array:
    """Quaternion (4,) of the target hand's per-episode tilt: about a uniformly random
    axis, by ``angle`` radians if given, else by a Gaussian angle of std ``noise``."""
    k_axis, k_angle = jax.random.split(rng)
    axis = random_direction(k_axis)
    if angle is None:
        angle = noise * jax.random.normal(k_angle, ())
    return spatial.axis_angle_quat(axis, jnp.asarray(angle, jnp.float32))


def yaw_pitch_quat(yaw: jax.Array, pitch: jax.Array) -> jax.Array:
    """Quaternion (4,) of a turn by ``pitch`` radians about the world y axis, then by ``yaw``
    about the world z axis (vertical): R = R_z(yaw) R_y(pitch). The agent's shoulder is
    at the origin and faces +x, so yaw turns the target hand left/right as the agent
    sees it and pitch tips it up/down."""
    z = jnp.array([0.0, 0.0, 1.0])
    y = jnp.array([0.0, 1.0, 0.0])
    return spatial.quat_mul(
        spatial.axis_angle_quat(z, jnp.asarray(yaw, jnp.float32)),
        spatial.axis_angle_quat(y, jnp.asarray(pitch, jnp.float32)),
    )


def yaw_pitch_roll_quat(yaw: jax.Array, pitch: jax.Array, roll: jax.Array) -> jax.Array:
    """Quaternion (4,) of R = R_z(yaw) R_y(pitch) R_x(roll) in the world frame: roll about
    the agent's line of sight (+x), then :func:`yaw_pitch_quat`."""
    x = jnp.array([1.0, 0.0, 0.0])
    return spatial.quat_mul(
        yaw_pitch_quat(yaw, pitch), spatial.axis_angle_quat(x, jnp.asarray(roll, jnp.float32))
    )


def orientation_tilt(rng: jax.Array, half_ranges: tuple[float, float, float]) -> jax.Array:
    """Quaternion (4,) of a yaw, pitch and roll each uniform in ``±half_ranges`` (radians)."""
    half = jnp.asarray(half_ranges, jnp.float32)
    yaw, pitch, roll = jax.random.uniform(rng, (3,), minval=-half, maxval=half)
    return yaw_pitch_roll_quat(yaw, pitch, roll)


def reflect_into_box(
    position: jax.Array, velocity: jax.Array, center: jax.Array, half: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """``position`` (3,) folded back into the box ``center`` ± ``half`` (3,) by mirroring at
    the walls it crossed, and ``velocity`` (3,) with those components reversed (a bounce:
    the speed stays). Assumes one step crosses a wall at most once (step < box)."""
    low, high = center - half, center + half
    below, above = position < low, position > high
    position = jnp.where(below, 2 * low - position, jnp.where(above, 2 * high - position, position))
    return position, jnp.where(below | above, -velocity, velocity)


POSE_METRICS = ("palm_goal_distance", "fingertip_goal_distance")
"""``metrics['pose/<name>']`` of every step: distance (metres) of the palm centre and the
mean distance of the five fingertips to their goals, the demonstrated final pose."""


@struct.dataclass
class EpisodeInfo:
    """Per-episode constants and counters kept in ``State.info['episode']``.

    Shapes are for one environment.
    """

    rng: jax.Array  # (2,) key for the next episode's randomisation
    demo: jax.Array  # () index of the demonstration
    start_step: jax.Array  # () t_s, control step of the demonstration at reset
    step: jax.Array  # () control steps taken in this episode
    target_pos: jax.Array  # (3,) target palm centre, world
    target_rot: jax.Array  # (3, 3) target palm orientation, world
    target_points: jax.Array  # (6, 3) target palm centre + fingertips, world
    target_frames: jax.Array  # (6, 3, 3) target palm + distal bodies, body-to-world
    goal_points: jax.Array  # (6, 3) goal palm + fingertips, world
    # (3,) m/s of the moving target (``EnvConfig.target_speed``); None: a static target.
    target_velocity: jax.Array | None = None
    # (delay, 24) actions not yet applied, oldest first (``EnvConfig.action_delay``; the
    # longest of ``action_delay_range``).
    action_queue: jax.Array | None = None
    # () this episode's delay, control steps (``EnvConfig.action_delay_range``); None: the
    # queue's length.
    action_delay: jax.Array | None = None
    # (K, 24) the policy's last K actions, most recent first (``observe_recent_actions``).
    recent_actions: jax.Array | None = None
    # The recorded partner (``EnvConfig.partner``): its palm pose at the closest
    # approach as placed (3,), (3, 3), (4,), and the row of the partner tables at step 0.
    partner_base_pos: jax.Array | None = None
    partner_base_rot: jax.Array | None = None
    partner_base_quat: jax.Array | None = None
    partner_row: jax.Array | None = None
    # () bool: whether the recorded partner replays its approach in this episode or holds
    # its placed pose and row as the static hand (``EnvConfig.partner_model_probability``
    # below 1); None: it replays.
    partner_replays: jax.Array | None = None
    # (3,) the partner's palm as the last observation saw it, sensing error included
    # (``EnvConfig.observe_target_velocity``): its next observed velocity starts here.
    seen_target_pos: jax.Array | None = None
    # (24,) the policy's previous action (``EnvConfig.action_rate_weight``).
    last_action: jax.Array | None = None


class HandInteractionEnv(Env):
    """One environment of a hand interaction task (single, unbatched)."""

    def __init__(self, config: EnvConfig = EnvConfig()):
        task = tasks.spec(config.task)
        self.config = config
        self.profile = profiles.env_profile(config.profile)
        self.target_box = profiles.target_box(config.profile, config.task, config.target_box)
        self.episode_length = config.episode_length or task.episode_length
        self.mj_model = scene.build_model(config.scene)
        self.n_substeps = round(config.control_dt / config.scene.timestep)
        if abs(self.n_substeps * config.scene.timestep - config.control_dt) > 1e-9:
            raise ValueError(
                f"control_dt={config.control_dt} is not a multiple of the physics timestep "
                f"{config.scene.timestep}"
            )
        self.physics = physics.make_physics(
            config.physics, self.mj_model, self.n_substeps, config.contact_distance
        )
        self.demos = select_demos(
            mocap.load_demonstrations(config.task, source=config.mocap_source, path=config.mocap),
            config.task,
            config.demos,
        )
        self.params = reward_params.build_task_params(
            self.demos, reward_weights(config), config.control_dt
        )
        self.variant = reward_params.variant_weights(self.params)
        """The reward variant of ``config``; reset puts it in ``info['reward_weights']``."""
        self._init_static_indices()
        self._init_target_tables()

    # ------------------------------------------------------------------ setup
    def _init_static_indices(self) -> None:
        m = self.mj_model
        name = lambda n: scene.AGENT + sh.hand_name(n)
        self.tip_sites = np.array([m.site(name(f"S_{t}")).id for t in sh.FINGERTIPS])
        self.palm_site = m.site(scene.AGENT + "palm_center").id
        self.target_palm_site = m.site(scene.TARGET + "palm_center").id
        arm_qadr = [m.joint(scene.AGENT + j).qposadr[0] for j in sh.ARM_JOINTS]
        hand_qadr = [m.joint(name(j)).qposadr[0] for j in sh.HAND_JOINTS]
        self.actuated_qadr = np.array(arm_qadr + hand_qadr)
        self.hand_qadr = np.array(hand_qadr)
        self.ctrl_lo, self.ctrl_hi = (
            m.actuator_ctrlrange[:, 0].copy(),
            m.actuator_ctrlrange[:, 1].copy(),
        )
        self.jnt_lo, self.jnt_hi = m.jnt_range[:, 0].copy(), m.jnt_range[:, 1].copy()
        self.chain = ik.make_chain(m, scene.AGENT + "palm_center")
        # Contact sensor of each geom (-1: none), as the scene's sensors define them.
        _, self.sensor_of_geom = physics.sensor_objects(m)
        self.target_mocap = np.array(
            [m.body_mocapid[m.body(scene.TARGET + link).id] for link in scene.TARGET_LINKS]
        )
        # The paper's observation: the target hand's links as the authors list them (palm,
        # fingers' knuckle to distal, thumb): all mocap links but forearm and lf metacarpal.
        self.observed_links = np.array(
            [i for i, link in enumerate(scene.TARGET_LINKS) if link not in PAPER_UNOBSERVED_LINKS]
        )
        rest = mujoco.MjData(m)
        self.mocap_pos0, self.mocap_quat0 = rest.mocap_pos.copy(), rest.mocap_quat.copy()
        # Distal-coupled joints follow their J1 in the start posture.
        self.coupled = np.array(
            [
                (m.joint(name(d)).qposadr[0], m.joint(name(p)).qposadr[0])
                for d, p in sh.COUPLED_DISTAL_JOINTS.items()
            ]
        )

    def _init_target_tables(self) -> None:
        """Target-hand poses in the palm frame for every demo and control step of its
        window (past its end: its last frame), and the recorded partner's palm path."""
        tables = partner.partner_tables(
            self.demos,
            np.asarray(self.params.t_min_frame),
            self.config.control_dt,
            self.config.partner_share,
        )
        # float32 angles, as the reward's references hold them: a static target's
        # poses are those of Algorithm 1's reference rows.
        joints = tables.joints.astype(np.float32)  # (n_demos, L, 20)
        n, length = joints.shape[:2]
        poses = scene.target_poses(joints.reshape(n * length, 20))
        reshape = lambda x: jnp.asarray(x.reshape((n, length) + x.shape[1:]), jnp.float32)
        self.link_pos = reshape(poses.link_pos)
        self.link_quat = reshape(poses.link_quat)
        self.point_pos = reshape(poses.point_pos)
        self.point_rot = reshape(poses.point_rot)
        self.partner_pos = jnp.asarray(tables.palm_pos, jnp.float32)
        self.partner_rot = jnp.asarray(tables.palm_rot, jnp.float32)
        quats = [_rot_to_quat(r) for r in tables.palm_rot.reshape(-1, 3, 3)]
        self.partner_quat = jnp.asarray(np.reshape(quats, (n, length, 4)), jnp.float32)
        center, rot = place_target(self.params, self.config.task, self.config.contact_point)
        self.target_center = jnp.asarray(center, jnp.float32)
        self.target_rot = jnp.asarray(rot, jnp.float32)
        self.target_quat = jnp.asarray(_rot_to_quat(rot), jnp.float32)

    def variant_for(self, weights: reward_params.RewardWeights) -> reward_params.VariantWeights:
        """The reward variant ``weights`` as the arrays ``info['reward_weights']`` holds:
        an episode whose state carries them is rewarded by that variant (the population
        trainer gives each member its own)."""
        params = reward_params.build_task_params(self.demos, weights, self.config.control_dt)
        return reward_params.variant_weights(params)

    # ----------------------------------------------------------- Brax Env API
    @property
    def observation_size(self) -> int:
        state = jax.eval_shape(self.reset, jax.random.PRNGKey(0))
        return state.obs.shape[-1]

    @property
    def action_size(self) -> int:
        return self.mj_model.nu

    @property
    def backend(self) -> str:
        return self.physics.name

    def reserve(self, worlds: int) -> None:
        self.physics.reserve(worlds)

    def describe(self) -> str:
        source = self.demos[0].source if self.demos else "no"
        return f"{len(self.demos)} demonstrations ({source}), {self.backend} physics"

    def pose(self, pipeline_state) -> dict[str, jax.Array]:
        """qpos (nq,), mocap_pos (nmocap, 3), mocap_quat (nmocap, 4): what renders a state."""
        return {k: getattr(pipeline_state, k) for k in ("qpos", "mocap_pos", "mocap_quat")}

    def reset(self, rng: jax.Array) -> State:
        """Start an episode with the paper's randomisation. rng: (2,) key."""
        return self.reset_with(rng)

    def reset_with(
        self, rng: jax.Array, tilt: jax.Array | None = None, speed: jax.Array | None = None
    ) -> State:
        """:meth:`reset` with the target's orientation and speed given as data (robustness
        sweeps vmap one compiled reset over a grid of them).

        Args:
          rng: (2,) key of everything else (demonstration, position, start, ...).
          tilt: (4,) quaternion turning the target hand from its nominal orientation about
            its palm centre (see :func:`yaw_pitch_quat`); None draws the configured tilt.
          speed: () m/s of the moving target; needs ``target_speed`` set (not None).
        """
        if speed is not None and not moving(self.config):
            raise ValueError(
                "reset_with(speed=...) needs a moving target: build the env with "
                "target_speed set (e.g. 0.0)"
            )
        # Full float32 for the start pose's IK and forward kinematics too (see physics).
        with jax.default_matmul_precision("highest"):
            return self._reset(rng, tilt, speed)

    def _reset(self, rng: jax.Array, tilt: jax.Array | None, speed: jax.Array | None) -> State:
        # Keys of the moving target come from the reset's key, folded: the draws below
        # stay those of a static target's episode.
        k_motion = jax.random.fold_in(rng, 1)
        rng, k_demo, k_start, k_frame, k_box, k_pos, k_joint, k_rot = jax.random.split(rng, 8)
        p = self.params
        demo = jax.random.randint(k_demo, (), 0, p.t_min_step.shape[0])
        t_min = p.t_min_step[demo]
        latest = jnp.maximum(t_min - self.config.start_offset_steps, 1)
        start = jax.random.randint(k_start, (), 1, latest + 1)
        frame = jax.random.randint(k_frame, (), start, jnp.maximum(t_min, start) + 1)

        target_pos = self.target_center + self._box_offset(k_box)
        applies = self._partner_models_apply(jax.random.fold_in(k_motion, 4))
        if tilt is None and self.config.target_orientation_range is not None:
            tilt = orientation_tilt(k_rot, self.config.target_orientation_range)
            tilt = jnp.where(applies["orientation"], tilt, jnp.array([1.0, 0.0, 0.0, 0.0]))
        elif tilt is None:
            tilt = target_tilt(
                k_rot, self.config.target_rotation_noise, self.config.target_rotation_angle
            )
        target_quat = spatial.quat_mul(tilt, self.target_quat)
        target_rot = spatial.quat_to_mat(tilt) @ self.target_rot
        base = (target_pos, target_rot, target_quat)
        recorded = self.config.partner == "recorded"
        if recorded:
            low, high = self.config.partner_lag
            lag = jax.random.randint(jax.random.fold_in(k_motion, 3), (), low, high + 1)

        def target_at(step: jax.Array) -> tuple:
            """The target hand while the agent starts at demonstration step ``step``:
            its palm (position, rotation, quaternion), its partner-table row and
            :meth:`_target_at`'s arrays. Static: the drawn frame, wherever the agent
            starts; recorded: the partner's own time, ``step`` + the episode's lag."""
            held = base, frame, self._target_at(demo, frame, *base)
            if not recorded:
                return held
            row = jnp.clip(step + lag, 0, self.partner_pos.shape[1] - 1)
            pose = self._partner_pose(demo, row, base)
            replayed = pose, row, self._target_at(demo, row, *pose)
            if applies["recorded"] is True:
                return replayed
            return jax.tree.map(functools.partial(jnp.where, applies["recorded"]), replayed, held)

        def start_pose(
            step: jax.Array, backoff: jax.Array
        ) -> tuple[jax.Array, jax.Array, jax.Array]:
            """The actor's demonstrated palm pose and finger angles at ``step``, with the
            episode's (fixed) start noise, the palm moved ``backoff`` metres farther
            from the target palm along the line between the two."""
            (palm_pos, palm_rot_world, _), _, (_, _, points, _, _) = target_at(step)
            palm_goal = palm_pos + p.ref_palm_pos[demo, step] @ palm_rot_world.T + position_noise
            away = palm_goal - points[0]
            palm_goal = palm_goal + backoff * away / jnp.maximum(jnp.linalg.norm(away), 1e-6)
            palm_rot = palm_rot_world @ p.ref_palm_rot[demo, step]
            return palm_goal, palm_rot, p.ref_angles[demo, step] + joint_noise

        def mocap_at(step: jax.Array) -> tuple[jax.Array, jax.Array]:
            _, _, (link_pos, link_quat, *_) = target_at(step)
            return (
                jnp.asarray(self.mocap_pos0, jnp.float32).at[self.target_mocap].set(link_pos),
                jnp.asarray(self.mocap_quat0, jnp.float32).at[self.target_mocap].set(link_quat),
            )

        position_noise = self.config.start_position_noise * jax.random.normal(k_pos, (3,))
        joint_noise = self.config.start_joint_noise * jax.random.normal(k_joint, (20,))
        start, data = self._separated_start(mocap_at, start, start_pose)
        (target_pos, target_rot, _), row, arrays = target_at(start)
        _, _, target_points, target_frames, goal_points = arrays

        episode = EpisodeInfo(
            rng=rng,
            demo=demo,
            start_step=start,
            step=jnp.zeros((), jnp.int32),
            target_pos=target_pos,
            target_rot=target_rot,
            target_points=target_points,
            target_frames=target_frames,
            goal_points=goal_points,
        )
        if moving(self.config):
            if speed is None and self.config.target_speed_range is not None:
                low, high = self.config.target_speed_range
                speed = jax.random.uniform(
                    jax.random.fold_in(k_motion, 1), (), minval=low, maxval=high
                )
                speed = jnp.where(applies["motion"], speed, 0.0)
            elif speed is None:
                speed = self.config.target_speed
            episode = episode.replace(
                target_velocity=jnp.asarray(speed, jnp.float32) * random_direction(k_motion)
            )
        if self.config.partner == "recorded":
            episode = episode.replace(
                partner_base_pos=base[0],
                partner_base_rot=base[1],
                partner_base_quat=base[2],
                partner_row=row,
                partner_replays=None if applies["recorded"] is True else applies["recorded"],
            )
        hold = self.action_for(data.ctrl)  # the set-points of the start pose
        delays = self.config.action_delay_range
        longest = self.config.action_delay if delays is None else delays[1]
        if longest > 0:
            queue = jnp.broadcast_to(hold, (longest,) + hold.shape)
            episode = episode.replace(action_queue=queue)
        if delays is not None:
            key = jax.random.fold_in(k_motion, 5)
            delay = jax.random.randint(key, (), delays[0], delays[1] + 1)
            episode = episode.replace(action_delay=delay)
        if self.config.observe_recent_actions:
            recent = jnp.broadcast_to(hold, (self.config.observe_recent_actions,) + hold.shape)
            episode = episode.replace(recent_actions=recent)
        if self.config.action_rate_weight > 0:
            episode = episode.replace(last_action=hold)
        if self.config.observe_target_velocity:  # observed still at the first step
            episode = episode.replace(seen_target_pos=self.seen_target_pos(episode))
        features = self._features(self.physics.readings(data), episode, data)
        zero = jnp.zeros(())
        terms = {k: zero for k in rewards.TERMS + self._extra_terms() + ("total",)}
        metrics = {f"reward/{k}": v for k, v in terms.items()} | {"success": zero, "diverged": zero}
        metrics |= {f"contact/{name}": zero for name in sh.CONTACT_SENSORS}
        metrics |= {f"pose/{name}": zero for name in POSE_METRICS}
        return State(
            pipeline_state=data,
            obs=self._observation(features, episode),
            reward=zero,
            done=zero,
            metrics=metrics,
            info={
                "episode": episode,
                "truncation": zero,
                "success": zero,
                "reward_weights": self.variant,
            },
        )

    def _extra_terms(self) -> tuple[str, ...]:
        """Reward terms this config adds to the paper's (``rewards.TERMS``)."""
        return ("action_rate",) if self.config.action_rate_weight > 0 else ()

    def _partner_models_apply(self, rng: jax.Array) -> dict[str, jax.Array | bool]:
        """Whether each partner model (orientation, motion, recorded) applies to the
        episode keyed ``rng``: independent draws with ``partner_model_probability``;
        Python True for every model when it is 1 (nothing drawn, nothing traced)."""
        probability = self.config.partner_model_probability
        names = ("orientation", "motion", "recorded")
        if probability == 1:
            return dict.fromkeys(names, True)
        draws = jax.random.bernoulli(rng, probability, (len(names),))
        return {name: draws[i] for i, name in enumerate(names)}

    def _start_qpos(
        self, palm_goal: jax.Array, palm_rot: jax.Array, fingers: jax.Array
    ) -> jax.Array:
        """Joint positions (nq,) that put the palm centre at ``palm_goal`` (3,) with
        orientation ``palm_rot`` (3, 3) by IK, and the fingers at ``fingers`` (20,)."""
        arm_q = ik.solve(
            self.chain, palm_goal, palm_rot, IK_SEED, iterations=self.config.ik_iterations
        )
        qpos = jnp.zeros(self.mj_model.nq)
        qpos = qpos.at[self.chain.qpos_adr].set(arm_q)
        qpos = qpos.at[self.hand_qadr[2:]].set(fingers[2:])  # wrist comes from the IK
        qpos = qpos.at[self.coupled[:, 0]].set(qpos[self.coupled[:, 1]] * sh.DISTAL_COUPLING)
        return jnp.clip(qpos, self.jnt_lo, self.jnt_hi)

    def _separated_start(
        self,
        mocap_at: Callable[[jax.Array], tuple[jax.Array, jax.Array]],
        start: jax.Array,
        start_pose: Callable[[jax.Array, jax.Array], tuple[jax.Array, jax.Array, jax.Array]],
    ) -> tuple[jax.Array, Any]:
        """Forward the start pose, moving the start earlier in the demonstration (and,
        from its first step, farther out) while the hands interpenetrate.

        The demonstrated pose through the arm's IK (which misses by ~3 cm and ~25 deg:
        the robot arm is not the human's) and the Shadow hand's geometry (not the
        human's) can put the agent's fingers centimetres into the target hand, most
        often in the last few tenths of a second before the demonstrated contact (38 %
        of handshake starts on the synthetic demonstrations, 61 % on the recordings).
        The solver would then spring the hands apart in the first steps, and MJX's box
        collisions resolve such depths otherwise than native MuJoCo. The demonstration
        itself is the first remedy: earlier, the actor's hand was farther out. While
        the deepest agent-target penetration exceeds ``start_max_penetration``, the
        start moves ``start_backoff_steps`` control steps earlier; once at step 1 (the
        recorded claps begin 1-10 steps before contact, fingers already overlapping),
        each further move backs the palm ``start_backoff_distance`` away from the
        target's along the line between the palm centres -- for flat hands that
        separates them, where interlocked handshake fingers would not be freed by it.
        At most ``start_retreats`` moves; starts without penetration stay as drawn.

        Args:
          mocap: the target hand's mocap poses, (nmocap, 3) positions and (nmocap, 4)
            quaternions.
          start: () drawn start step t_s.
          start_pose: (step, backoff metres) -> (palm goal (3,), palm rotation (3, 3),
            finger angles (20,)).
        Returns:
          the start step used and the physics state at rest at its pose.
        """
        cfg = self.config

        def attempt(carry):
            step, backoff, _, _, tries = carry
            at_first = step <= 1
            retreat = tries > 0
            backoff = jnp.where(retreat & at_first, backoff + cfg.start_backoff_distance, backoff)
            earlier = jnp.maximum(step - cfg.start_backoff_steps, 1)
            step = jnp.where(retreat & ~at_first, earlier, step)
            qpos = self._start_qpos(*start_pose(step, backoff))
            state = self.physics.pose(qpos, *mocap_at(step))
            return step, backoff, state, self.physics.readings(state).penetration, tries + 1

        def penetrating(carry):
            step, _, _, depth, tries = carry
            can_move = (step > 1) | (cfg.start_backoff_distance > 0)
            retry = (tries <= cfg.start_retreats) & ((tries == 0) | can_move)
            return (depth > cfg.start_max_penetration) & retry

        # One traced forward pass serves the drawn start and every retreat.
        zero = jnp.zeros(())
        shapes = jax.eval_shape(self.physics.pose, jnp.zeros(self.mj_model.nq), *mocap_at(start))
        rest = jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), shapes)  # carry type only
        first = (start, zero, rest, jnp.full((), jnp.inf), jnp.zeros((), jnp.int32))
        step, _, state, _, _ = jax.lax.while_loop(penetrating, attempt, first)
        return step, state

    def ctrl_for(self, action: jax.Array) -> jax.Array:
        """Set-points (24,) of the actuators for ``action`` (24,) in [-1, 1]."""
        return self.ctrl_lo + 0.5 * (action + 1.0) * (self.ctrl_hi - self.ctrl_lo)

    def action_for(self, setpoints: jax.Array) -> jax.Array:
        """The action (24,) in [-1, 1] whose set-points :meth:`ctrl_for` makes ``setpoints``
        (24,) (clipped to the actuators' ranges): the inverse of its mapping."""
        action = 2.0 * (setpoints - self.ctrl_lo) / (self.ctrl_hi - self.ctrl_lo) - 1.0
        return jnp.clip(action, -1.0, 1.0)

    def step(self, state: State, action: jax.Array) -> State:
        """Advance one control period. action: (24,) in [-1, 1]."""
        action = jnp.clip(action, -1.0, 1.0)
        before = state.pipeline_state
        data, episode = self._advance_partner(before, state.info["episode"])
        # A moving partner glides from the last period's pose (``partner_motion``).
        glide = self.config.partner_motion == "continuous" and self._partner_moves(episode)
        mocap_from = (before.mocap_pos, before.mocap_quat) if glide else None
        applied = action
        if episode.action_queue is not None:  # the action of `delay` steps ago; queue this one
            queue = episode.action_queue
            applied = queue[0]
            if episode.action_delay is not None:  # this episode's delay, <= the queue's length
                waited = queue[queue.shape[0] - jnp.maximum(episode.action_delay, 1)]
                applied = jnp.where(episode.action_delay > 0, waited, action)
            episode = episode.replace(action_queue=jnp.concatenate([queue[1:], action[None]]))
        if episode.recent_actions is not None:
            recent = jnp.concatenate([action[None], episode.recent_actions[:-1]])
            episode = episode.replace(recent_actions=recent)
        data = self.physics.step(data, self.ctrl_for(applied), mocap_from=mocap_from)
        readings = self.physics.readings(data)
        episode = episode.replace(step=episode.step + 1)
        features = self._features(readings, episode, data)

        params = reward_params.with_variant(self.params, state.info["reward_weights"])
        p = jax.tree.map(lambda x: x[episode.demo], params)
        terms = rewards.compute_rewards(
            p,
            episode.start_step + episode.step,
            hand_points=features["points"],
            target_points=episode.target_points,
            target_frames=episode.target_frames,
            hand_angles=features["hand_angles"],
            contacts=features["contacts"],
            action=action,
        )
        if episode.last_action is not None:  # smoothness, beside the paper's six terms
            rate = -self.config.action_rate_weight * jnp.sum(
                jnp.square(action - episode.last_action)
            )
            terms = terms | {"action_rate": rate, "total": terms["total"] + rate}
            episode = episode.replace(last_action=action)
        success = rewards.success(features["contacts"], p.success_groups).astype(jnp.float32)

        finite = readings.finite
        truncated = episode.step >= self.episode_length
        done = jnp.where(finite, truncated, True).astype(jnp.float32)
        # A diverged simulation ends its episode as a truncation at the last finite
        # observation, with the last finite reward: a learner bootstraps as if the episode
        # went on, so blowing up the physics is no escape from negative rewards (as a
        # 0-reward termination would be), and no non-finite number reaches it.
        obs = jnp.where(finite, self._observation(features, episode), state.obs)
        if episode.seen_target_pos is not None:
            episode = episode.replace(seen_target_pos=self.seen_target_pos(episode))
        reward = jnp.where(finite, terms["total"], state.reward)
        metrics = dict(state.metrics)  # entries that wrappers (e.g. Brax's) added stay
        metrics |= {f"reward/{k}": jnp.where(finite, v, 0.0) for k, v in terms.items()}
        metrics["reward/total"] = reward  # what the learner receives, diverged or not
        metrics["success"] = success
        metrics["diverged"] = 1.0 - finite.astype(jnp.float32)
        # Each sensor's reading: which of the required contacts a policy still misses.
        metrics |= {
            f"contact/{name}": jnp.where(finite, features["contacts"][i], 0.0)
            for i, name in enumerate(sh.CONTACT_SENSORS)
        }
        # How far the hand is from the demonstrated final pose (unweighted, metres).
        goal_distance = jnp.linalg.norm(episode.goal_points - features["points"], axis=-1)
        pose = {
            "palm_goal_distance": goal_distance[0],
            "fingertip_goal_distance": goal_distance[1:].mean(),
        }
        # NaN, not 0 m, after a divergence: blowing up is no way to the goal (means skip it).
        metrics |= {f"pose/{k}": jnp.where(finite, v, jnp.nan) for k, v in pose.items()}
        info = dict(state.info)
        info.update(
            episode=episode,
            truncation=jnp.where(finite, truncated, True).astype(jnp.float32),
            success=success,
        )
        return state.replace(
            pipeline_state=data, obs=obs, reward=reward, done=done, metrics=metrics, info=info
        )

    def _move_target(self, data, episode: EpisodeInfo) -> tuple[Any, EpisodeInfo]:
        """The moving target one control period on (before the physics step of the period):
        its mocap links, palm, points and goals shifted alike (the imitation reference is
        computed from them). It turns to a fresh random direction whenever the time after
        the step, (step + 1)·dt, enters a new ``target_turn_period``."""
        cfg = self.config
        per_turn = cfg.target_turn_period / cfg.control_dt  # control steps per direction
        now = episode.step.astype(jnp.float32)
        turns = jnp.floor((now + 1) / per_turn + 1e-4) > jnp.floor(now / per_turn + 1e-4)
        velocity = episode.target_velocity
        fresh = jnp.linalg.norm(velocity) * random_direction(
            jax.random.fold_in(jax.random.fold_in(episode.rng, 2), episode.step)
        )
        velocity = jnp.where(turns, fresh, velocity)
        # The recorded partner's path is relative to its placed pose: that pose moves.
        anchor = (
            episode.target_pos if episode.partner_base_pos is None else episode.partner_base_pos
        )
        position, velocity = reflect_into_box(
            anchor + velocity * cfg.control_dt,
            velocity,
            self.target_center,
            jnp.asarray(cfg.target_motion_box, jnp.float32),
        )
        shift = position - anchor
        mocap_pos = data.mocap_pos.at[self.target_mocap].add(shift)
        episode = episode.replace(
            target_pos=episode.target_pos + shift,
            target_points=episode.target_points + shift,
            goal_points=episode.goal_points + shift,
            target_velocity=velocity,
        )
        if episode.partner_base_pos is not None:
            episode = episode.replace(partner_base_pos=position)
        return data.replace(mocap_pos=mocap_pos), episode

    @staticmethod
    def _partner_moves(episode: EpisodeInfo) -> bool:
        """Whether this configuration's partner can move within an episode (known when
        tracing: the moving target's velocity or the recorded partner's row exist)."""
        return episode.target_velocity is not None or episode.partner_row is not None

    def _advance_partner(self, data, episode: EpisodeInfo) -> tuple[Any, EpisodeInfo]:
        """The target hand one control period on, before the physics step of the period:
        moved (``target_speed``), then at its recorded pose of the period's end
        (``partner = 'recorded'``); unchanged for the paper's static target."""
        if episode.target_velocity is not None:
            data, episode = self._move_target(data, episode)
        if episode.partner_row is None:
            return data, episode
        row = jnp.clip(episode.partner_row + episode.step + 1, 0, self.partner_pos.shape[1] - 1)
        base = (episode.partner_base_pos, episode.partner_base_rot, episode.partner_base_quat)
        pos, rot, quat = self._partner_pose(episode.demo, row, base)
        if episode.partner_replays is not None:  # or it holds its placed pose and row
            row = jnp.where(episode.partner_replays, row, episode.partner_row)
            pos, rot, quat = jax.tree.map(
                functools.partial(jnp.where, episode.partner_replays), (pos, rot, quat), base
            )
        link_pos, link_quat, points, frames, goals = self._target_at(
            episode.demo, row, pos, rot, quat
        )
        data = data.replace(
            mocap_pos=data.mocap_pos.at[self.target_mocap].set(link_pos),
            mocap_quat=data.mocap_quat.at[self.target_mocap].set(link_quat),
        )
        episode = episode.replace(
            target_pos=pos,
            target_rot=rot,
            target_points=points,
            target_frames=frames,
            goal_points=goals,
        )
        return data, episode

    def _partner_pose(
        self, demo: jax.Array, row: jax.Array, base: tuple[jax.Array, jax.Array, jax.Array]
    ) -> tuple[jax.Array, jax.Array, jax.Array]:
        """The recorded partner's palm at partner-table ``row`` of ``demo``, its pose at
        the closest approach being ``base`` (position (3,), rotation (3, 3), quaternion
        (4,), world): the same three of the palm at that row."""
        base_pos, base_rot, base_quat = base
        return (
            base_pos + base_rot @ self.partner_pos[demo, row],
            base_rot @ self.partner_rot[demo, row],
            spatial.quat_mul(base_quat, self.partner_quat[demo, row]),
        )

    def _target_at(
        self,
        demo: jax.Array,
        row: jax.Array,
        pos: jax.Array,
        rot: jax.Array,
        quat: jax.Array,
    ) -> tuple[jax.Array, ...]:
        """The target hand of ``demo`` in its posture of table ``row`` with its palm at
        ``pos`` (3,), ``rot`` (3, 3) / ``quat`` (4,): mocap link positions (21, 3) and
        quaternions (21, 4), palm centre + fingertips (6, 3), their frames (6, 3, 3) and
        the reward's goal points (6, 3), all world."""
        to_world = lambda x: pos + x @ rot.T
        points = to_world(self.point_pos[demo, row])
        frames = rot @ self.point_rot[demo, row]
        goals = rewards.goal_positions(
            points, frames, self.params.j_min[demo], self.params.goal_offsets[demo]
        )
        return (
            to_world(self.link_pos[demo, row]),
            spatial.quat_mul(quat, self.link_quat[demo, row]),
            points,
            frames,
            goals,
        )

    def partner_schedule(self, state: State) -> dict[str, jax.Array]:
        """Where the partner's hand is, and what the policy observes of it, at every
        control step k = 0..T of the episode that ``state`` (a reset's, single env)
        starts: none of it depends on the agent's actions (the moving target's path and
        the sensing errors are keyed by the episode), so a player outside JAX can step
        the physics and build the observation from these and its own readings
        (:mod:`mjx_hands.export`). Arrays with a leading axis T + 1:

        * ``mocap_pos`` (T+1, nmocap, 3), ``mocap_quat`` (T+1, nmocap, 4): the target's
          mocap bodies in the physics step that ends at step k (k = 0: at reset);
        * as observed, sensing error included: ``target_pos`` (T+1, 3), ``target_points``,
          ``goal_points``, ``imitation_points`` (T+1, 6, 3), ``target_links`` (T+1, 21, 3);
        * ``imitation_active`` (T+1,) 0/1, the phase's flag.
        """

        def at(data, episode: EpisodeInfo) -> dict[str, jax.Array]:
            p = jax.tree.map(lambda x: x[episode.demo], self.params)
            offsets, _, active = rewards.reference_at(p, episode.start_step + episode.step)
            imitation = rewards.goal_positions(
                episode.target_points, episode.target_frames, p.j_min, offsets
            )
            error = self.sensing_error(episode)
            links = data.mocap_pos[self.target_mocap[self.observed_links]]
            return {
                "mocap_pos": data.mocap_pos,
                "mocap_quat": data.mocap_quat,
                "target_pos": episode.target_pos + error,
                "target_points": episode.target_points + error,
                "goal_points": episode.goal_points + error,
                "imitation_points": imitation + error,
                "target_links": links + error,
                "imitation_active": active.astype(jnp.float32),
            }

        def advance(carry, _):
            data, episode = self._advance_partner(*carry)
            episode = episode.replace(step=episode.step + 1)
            return (data, episode), at(data, episode)

        start = (state.pipeline_state, state.info["episode"])
        _, later = jax.lax.scan(advance, start, None, length=self.episode_length)
        return jax.tree.map(lambda a, b: jnp.concatenate([a[None], b]), at(*start), later)

    def points_in_target_frame(self, state: State) -> jax.Array:
        """The agent's palm centre and fingertips (6, 3) in the target palm's frame (its
        centre the origin, its axes those of the target palm), where the demonstrations'
        actor trajectories are: the naturalness metrics compare the two there."""
        episode = state.info["episode"]
        points = self.physics.readings(state.pipeline_state).points
        return (points - episode.target_pos) @ episode.target_rot

    # --------------------------------------------------------------- features
    def _box_offset(self, rng: jax.Array) -> jax.Array:
        """(3,) offset of the target palm from its nominal place, drawn from the
        profile's box (a second draw only where the box has a shift)."""
        box = self.target_box
        offset = jax.random.uniform(
            rng, (3,), minval=jnp.asarray(box.low), maxval=jnp.asarray(box.high)
        )
        if any(box.shift_low) or any(box.shift_high):
            offset = offset + jax.random.uniform(
                jax.random.fold_in(rng, 1),
                (3,),
                minval=jnp.asarray(box.shift_low),
                maxval=jnp.asarray(box.shift_high),
            )
        axes = np.asarray(box.axes, np.float32)
        if np.array_equal(axes, np.eye(3)):
            return offset
        return jnp.asarray(axes) @ offset

    def _features(
        self, readings: physics.Readings, episode: EpisodeInfo, data: Any
    ) -> dict[str, jax.Array]:
        """Everything the reward and the observation read from the simulation."""
        p = jax.tree.map(lambda x: x[episode.demo], self.params)
        offsets, _, imitation_active = rewards.reference_at(p, episode.start_step + episode.step)
        imitation_points = rewards.goal_positions(
            episode.target_points, episode.target_frames, p.j_min, offsets
        )
        features = {
            "qpos": readings.qpos,
            "qvel": readings.qvel,
            "points": readings.points,
            "hand_angles": readings.qpos[self.hand_qadr],
            "contacts": readings.touch
            if self.profile.contact_rule == "touch"
            else readings.contacts,
            "imitation_points": imitation_points,
            "imitation_active": imitation_active.astype(jnp.float32),
        }
        if self.profile.observation == "paper":  # only its observation reads them
            features["target_links"] = data.mocap_pos[self.target_mocap[self.observed_links]]
        return features

    def sensing_error(self, episode: EpisodeInfo) -> jax.Array:
        """The observed target's position error (3,) metres at this step of the episode
        (``target_position_noise``; zeros without it). Keyed by the episode and its step,
        so nothing else the episode draws changes."""
        noise = self.config.target_position_noise
        if noise == 0:
            return jnp.zeros(3)
        key = jax.random.fold_in(jax.random.fold_in(episode.rng, SENSING_KEY), episode.step)
        return noise * jax.random.normal(key, (3,))

    def seen_target_pos(self, episode: EpisodeInfo) -> jax.Array:
        """The partner's palm (3,) as observed at this step: true position + sensing error."""
        return episode.target_pos + self.sensing_error(episode)

    def _observation(self, f: dict[str, jax.Array], episode: EpisodeInfo) -> jax.Array:
        error = self.sensing_error(episode)
        velocity = None
        if episode.seen_target_pos is not None:  # this step's observed palm minus the last's
            seen = episode.target_pos + error
            velocity = (seen - episode.seen_target_pos) / jnp.float32(self.config.control_dt)
        if self.config.target_position_noise:
            f = f | {"imitation_points": f["imitation_points"] + error}
            if "target_links" in f:
                f = f | {"target_links": f["target_links"] + error}
            episode = episode.replace(
                target_pos=episode.target_pos + error,
                target_points=episode.target_points + error,
                goal_points=episode.goal_points + error,
            )
        if self.profile.observation == "paper":
            # The authors' _get_obs: joint angles, joint velocities x dt, the target
            # hand's link positions (world) and the touch sensors; no goal, no time.
            return jnp.concatenate(
                [
                    f["qpos"],
                    self.config.control_dt * f["qvel"],
                    f["target_links"].reshape(-1),
                    f["contacts"],
                ]
            )
        relative_points = f["points"] - episode.target_pos
        phase = jnp.stack([episode.step / self.episode_length, f["imitation_active"]]).astype(
            jnp.float32
        )
        parts = [
            f["qpos"],
            0.1 * f["qvel"],
            f["contacts"],
            relative_points.reshape(-1),
            (episode.goal_points - f["points"]).reshape(-1),
            ((f["imitation_points"] - f["points"]) * f["imitation_active"]).reshape(-1),
            (episode.target_points - f["points"][0]).reshape(-1),
            phase,
        ]
        if velocity is not None:
            parts.append(velocity)
        if episode.recent_actions is not None:
            parts.append(episode.recent_actions.reshape(-1))
        return jnp.concatenate(parts)


def _rot_to_quat(rot: np.ndarray) -> np.ndarray:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.asarray(rot, np.float64).reshape(9))
    return quat


class BatchedEnv(Wrapper):
    """A batch of environments with automatic restarts (a Brax ``Wrapper`` of any
    :class:`mjx_hands.contract.InteractionEnv`; other attributes pass through).

    ``reset`` takes one key and returns a batched ``State``; ``step`` takes and
    returns batched states. An environment whose episode ended starts a new one with
    fresh randomisation (its own stored key) inside ``step``; the returned state
    keeps the finished step's ``reward``, ``done`` and ``metrics`` and stores its
    final observation in ``info['terminal_obs']`` so a learner can bootstrap
    truncated episodes from the true last observation.

    Episodes have a fixed length and start together, so they end together: the
    (comparatively costly) reset with its IK runs under ``lax.cond`` only on steps
    where at least one environment finished.

    Entries of ``info`` other than ``episode`` (e.g. ``reward_weights``) persist across
    restarts: what a trainer put there holds for the environment's whole life.
    """

    def __init__(self, env: InteractionEnv, num_envs: int):
        super().__init__(env)
        self.num_envs = num_envs

    def reset(self, rng: jax.Array) -> State:
        """rng: (2,) -> State with leading axis num_envs."""
        state = jax.vmap(self.env.reset)(jax.random.split(rng, self.num_envs))
        state.info["terminal_obs"] = state.obs
        return state

    def step(self, state: State, action: jax.Array) -> State:
        """state: batched State; action: (num_envs, 24)."""
        state = jax.vmap(self.env.step)(state, action)
        state.info["terminal_obs"] = state.obs

        def restart(state: State) -> State:
            fresh = jax.vmap(self.env.reset)(state.info["episode"].rng)
            done = state.done > 0

            def pick(new, old):
                return jnp.where(done.reshape(done.shape + (1,) * (old.ndim - 1)), new, old)

            info = dict(state.info)
            info["episode"] = jax.tree.map(pick, fresh.info["episode"], state.info["episode"])
            return state.replace(
                pipeline_state=jax.tree.map(pick, fresh.pipeline_state, state.pipeline_state),
                obs=pick(fresh.obs, state.obs),
                info=info,
            )

        return jax.lax.cond(jnp.any(state.done > 0), restart, lambda s: s, state)


def make_env(task: str = "handshake", num_envs: int | None = None, **overrides: Any):
    """An environment of ``task`` ('handshake', 'handclap', 'et').

    Args:
      num_envs: None for a single environment, else a :class:`BatchedEnv` of that size.
      **overrides: fields of :class:`EnvConfig` (e.g. ``reward='baseline1'``).
    """
    fields = {f.name for f in dataclasses.fields(EnvConfig)}
    unknown = sorted(set(overrides) - fields)
    if unknown:
        raise TypeError(f"unknown EnvConfig field(s) {unknown}; valid: {sorted(fields)}")
    env = HandInteractionEnv(EnvConfig(task=task, **overrides))
    return env if num_envs is None else BatchedEnv(env, num_envs)


def scoring_env(config: EnvConfig) -> HandInteractionEnv:
    """The environment that scores policies of ``config``'s task on the same episodes,
    static- and robust-trained alike: ``config`` with the paper's static partner
    (``env_config.static_partner``); one object per resulting setting, so that every
    policy of a program shares its compiled rollouts."""
    return env_for(static_partner(config))


@functools.lru_cache(maxsize=32)
def env_for(config: EnvConfig) -> HandInteractionEnv:
    """One environment object per config in a program, so that everything cached per
    environment (compiled rollouts and resets) is shared by every policy scored in it."""
    return HandInteractionEnv(config)


def model_sizes(env: HandInteractionEnv) -> dict[str, int]:
    """Sizes that drive physics cost: DoFs, actuators, contacts and MJX constraint rows."""
    m = env.mj_model
    return {
        "nq": m.nq,
        "nv": m.nv,
        "nu": m.nu,
        "nmocap": m.nmocap,
        "ngeom": m.ngeom,
        "contact_pairs": m.npair,
        "equality_rows": m.neq,
        **physics.mjx_sizes(m),
        "substeps": env.n_substeps,
    }


def _main() -> None:
    import argparse

    parser = argparse.ArgumentParser(
        description="Build a task environment, print its model sizes and time random steps."
    )
    parser.add_argument("--task", default="handshake", choices=TASKS)
    parser.add_argument("--num-envs", type=int, default=128, help="batch size")
    parser.add_argument("--steps", type=int, default=20, help="timed control steps")
    parser.add_argument(
        "--mocap-source", default="auto", choices=("auto", "optitrack", "synthetic")
    )
    parser.add_argument("--physics", default="auto", choices=("auto",) + physics.PHYSICS)
    args = parser.parse_args()

    env = make_env(
        args.task, num_envs=args.num_envs, mocap_source=args.mocap_source, physics=args.physics
    )
    single = env.unwrapped
    print(
        f"task {args.task}: {len(single.demos)} demonstrations ({single.demos[0].source}), "
        f"{single.physics.name} physics"
    )
    for key, value in model_sizes(single).items():
        print(f"  {key:16s} {value}")
    print(f"  observation_size {env.observation_size}, action_size {env.action_size}")

    reset, step = jax.jit(env.reset), jax.jit(env.step)
    key = jax.random.PRNGKey(0)
    t0 = time.perf_counter()
    state = jax.block_until_ready(reset(key))
    t_reset = time.perf_counter() - t0
    actions = jax.random.uniform(key, (args.steps, args.num_envs, env.action_size), minval=-1.0)
    t0 = time.perf_counter()
    state = jax.block_until_ready(step(state, actions[0]))
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    for a in actions[1:]:
        state = step(state, a)
    jax.block_until_ready(state)
    elapsed = time.perf_counter() - t0
    n = (args.steps - 1) * args.num_envs
    print(f"  reset (compile+run) {t_reset:.1f} s, first step (compile+run) {t_compile:.1f} s")
    print(
        f"  batch {args.num_envs}: {n / elapsed:,.0f} control steps/s, "
        f"{n * single.n_substeps / elapsed:,.0f} physics steps/s on {jax.devices()[0].platform}"
    )


if __name__ == "__main__":
    _main()

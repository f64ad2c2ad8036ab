"""Which target orientations the arm can reach: inverse kinematics of the agent's contact
point to its goal, per cell of the robustness sweep's yaw x pitch grid.

    python -m benchmarks.reachability --task et --mocap-source optitrack \
        --out benchmarks/partners/reachability_et.json

For every cell (the target hand turned about its palm centre, as ``mjx_hands.robustness``
turns it) and every episode of the sweep's seed (their demonstrations and target
positions), the agent's contact point (``CONTACT_POINTS``: the index fingertip for E.T.,
the palm centre for the handshake and the clap) is asked to reach its goal (Algorithm 1's
goal-centric target of that point at the moment of contact, which turns with the target)
by damped least-squares IK over every joint from the shoulder to that point, within
their limits, position only, from the episode's start pose and from ``--restarts``
random poses. Reported per cell: the share of episodes whose best solution ends within
``--tolerance`` of the goal, and the median distance. A goal out of reach makes the
cell's success depend on touching elsewhere; a reachable one says the arm's kinematics
do not forbid it.

A handshake or a clap needs the palm turned as well as placed: with
``--rotation-weight W`` (metres per radian, > 0; palm tasks) the IK also turns the palm to
its demonstrated orientation at contact (the demonstration's palm relative to the target
palm at t_min, turned with the target). The robot arm misses the human's pose already at
the nominal pose (by ~3 cm and ~23 deg), where the policies succeed; so an episode counts
as reached in a cell where its misses exceed its own at the nominal pose by no more than
``--tolerance`` and ``--angle-tolerance`` degrees. The median angle is reported either way. Kinematics only: collisions between the hands are not checked, and the
index finger's distal joint moves freely in the IK where the hand couples it to the middle
one (one degree of freedom more than the hand has).

``--carry RUN_DIR`` asks a sharper question of a trained policy: the contacts it makes at
the nominal pose, carried with the turned partner. Each of the sweep's episodes that the
policy ends in success at the nominal pose gives a contact configuration (its last
state: the palm's pose relative to the target palm, every finger joint); per cell, the
arm and wrist (6 joints, position and orientation, ``--carry-rotation-weight`` m per
radian, from that state's joints and ``--restarts`` random ones, within the joint limits
as far as the policy's own states press past them) are asked to put the
palm in the same pose relative to the turned target, the fingers kept, and native MuJoCo
then checks the task's success condition in that configuration (every success group's
phalanx within the environment's contact distance of the partner) and that nothing
presses deeper into the partner than it did at the nominal pose (``--carry-depth`` m
more at most). The share of such episodes per cell is a sufficient condition, not a
necessary one: where it is high the nominal solution fits the turned partner and a
policy has only to find it; where it is low the policy must find contacts of another
shape, which the arm may or may not allow.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from benchmarks import machine
from benchmarks.contact_hold import phalanx_distances
from mjx_hands import env as env_lib
from mjx_hands import ik, physics, policies, robustness, rollouts, scene, shadow_hand
from mjx_hands.env_config import MOCAP_SOURCES, EnvConfig
from mjx_hands.robustness import angle_grid
from mjx_hands.rollouts import EVAL_SEED

CONTACT_POINTS = {"et": "fftip", "handshake": "palm", "handclap": "palm"}
"""Per task, the agent's point (``shadow_hand.HAND_POINTS``) that must reach its goal."""

POINT_SITES = {"palm": "palm_center"} | {f"{f}tip": f"robot0:S_{f}tip" for f in shadow_hand.FINGERS}
"""The agent's site of each hand point."""


def contact_rotation(env, episode) -> jax.Array:
    """(3, 3) the agent palm's demonstrated orientation at the closest approach (t_min),
    world, for ``episode``'s demonstration and (turned) target palm."""
    demo = episode.demo
    return episode.target_rot @ env.params.ref_palm_rot[demo, env.params.t_min_step[demo]]


def angle_between(rot: jax.Array, goal: jax.Array) -> jax.Array:
    """Geodesic angle (radians) between two (3, 3) rotations."""
    cos = 0.5 * (jnp.trace(goal.T @ rot) - 1.0)
    return jnp.arccos(jnp.clip(cos, -1.0, 1.0))


def best_reach(
    env,
    chain: ik.Chain,
    row: int,
    key,
    tilt,
    restarts: int,
    iterations: int,
    rotation_weight: float = 0.0,
):
    """(starts, 2) distance (m) from the goal of hand point ``row`` and angle (radians)
    from the demonstrated palm orientation at contact, after IK from the episode's start
    pose and ``restarts`` uniform random poses, for one episode. ``rotation_weight`` 0
    solves for the position only (its angle is still reported)."""
    state = env.reset_with(key, tilt)
    episode = state.info["episode"]
    goal, goal_rot = episode.goal_points[row], contact_rotation(env, episode)
    lower, upper = jnp.asarray(chain.lower), jnp.asarray(chain.upper)
    starts = jax.random.uniform(
        jax.random.fold_in(key, 7), (restarts, lower.shape[0]), minval=lower, maxval=upper
    )
    starts = jnp.concatenate([state.pipeline_state.qpos[chain.qpos_adr][None], starts])
    solve = lambda q0: ik.solve(
        chain, goal, goal_rot, q0, iterations, rotation_weight=rotation_weight
    )
    reached, rot = jax.vmap(lambda q0: ik.forward(chain, solve(q0)))(starts)
    angle = jax.vmap(angle_between, in_axes=(0, None))(rot, goal_rot)
    return jnp.stack([jnp.linalg.norm(reached - goal, axis=-1), angle], axis=-1)


def reachability(
    task: str,
    mocap_source: str,
    max_angle: float,
    step: float,
    episodes: int,
    seed: int,
    restarts: int,
    iterations: int,
    tolerance: float,
    rotation_weight: float = 0.0,
    angle_tolerance: float = 10.0,
) -> dict:
    """Per yaw x pitch cell, the share of episodes whose contact point reaches its goal
    within ``tolerance`` m, with the median misses. With ``rotation_weight`` > 0 the palm
    is turned too, and an episode counts as reached where its position and angle misses
    exceed the same episode's at the nominal pose by no more than ``tolerance`` m and
    ``angle_tolerance`` degrees (the arm already misses the human's pose there)."""
    env = env_lib.HandInteractionEnv(
        EnvConfig(task=task, mocap_source=mocap_source, physics="native")
    )
    point = CONTACT_POINTS[task]
    if rotation_weight > 0 and point != "palm":
        raise ValueError(
            f"--rotation-weight: the palm's orientation is asked of palm tasks "
            f"only; {task}'s contact point is {point}"
        )
    chain = ik.make_chain(env.mj_model, scene.AGENT + POINT_SITES[point])
    row = shadow_hand.HAND_POINTS.index(point)
    angles = angle_grid(max_angle, step)
    yaw, pitch = np.meshgrid(np.radians(angles), np.radians(angles))  # rows: pitch
    tilts = jax.vmap(env_lib.yaw_pitch_quat)(jnp.asarray(yaw.ravel()), jnp.asarray(pitch.ravel()))
    keys = jax.random.split(jax.random.PRNGKey(seed), episodes)  # the sweep's episodes
    per_cell = jax.jit(
        jax.vmap(
            lambda tilt: jax.vmap(
                lambda k: best_reach(
                    env, chain, row, k, tilt, restarts, iterations, rotation_weight
                )
            )(keys)
        )
    )
    with jax.default_matmul_precision("highest"):
        misses = np.asarray(per_cell(tilts))  # (cells, episodes, starts, 2)
    # The best start per episode: by the IK's own objective (metres per radian).
    cost = misses[..., 0] ** 2 + (rotation_weight * misses[..., 1]) ** 2
    best = np.take_along_axis(misses, cost.argmin(axis=-1)[..., None, None], axis=2)[:, :, 0]
    distance, angle = best[..., 0], np.degrees(best[..., 1])  # (cells, episodes)
    shape = (angles.size, angles.size)
    if rotation_weight > 0:  # no worse than the same episode at the nominal pose
        nominal = angles.size * (angles.size // 2) + angles.size // 2  # yaw = pitch = 0
        reached = (distance <= distance[nominal] + tolerance) & (
            angle <= angle[nominal] + angle_tolerance
        )
    else:
        reached = distance <= tolerance
    return {
        "task": task,
        "demonstrations": mocap_source,
        "point": point,
        "chain_joints": int(chain.qpos_adr.size),
        "angles_deg": angles.tolist(),
        "episodes": episodes,
        "restarts": restarts,
        "ik_iterations": iterations,
        "tolerance_m": tolerance,
        "rotation_weight_m_per_rad": rotation_weight,
        "angle_tolerance_deg": angle_tolerance if rotation_weight > 0 else None,
        "reached": reached.mean(axis=1).reshape(shape).tolist(),
        "median_distance_m": np.median(distance, axis=1).reshape(shape).tolist(),
        "median_angle_deg": np.median(angle, axis=1).reshape(shape).tolist(),
    }


def relative_pose(pos, rot, frame_pos, frame_rot):
    """(3,), (3, 3): a pose (position, rotation) in the frame (``frame_pos``, ``frame_rot``)."""
    return frame_rot.T @ (pos - frame_pos), frame_rot.T @ rot


def carried_arm(
    chain: ik.Chain,
    rel_pos,
    rel_rot,
    target_pos,
    target_rot,
    q0,
    key,
    restarts: int,
    iterations: int,
    rotation_weight: float,
):
    """(6,) arm and wrist joints whose palm best takes the pose (``rel_pos``, ``rel_rot``)
    relative to a target palm at (``target_pos``, ``target_rot``): IK from ``q0`` and
    ``restarts`` uniform random joints, the best by the IK's own objective."""
    goal, goal_rot = target_pos + target_rot @ rel_pos, target_rot @ rel_rot
    lower, upper = jnp.asarray(chain.lower), jnp.asarray(chain.upper)
    starts = jax.random.uniform(key, (restarts, lower.shape[0]), minval=lower, maxval=upper)
    starts = jnp.concatenate([q0[None], starts])
    solve = lambda q: ik.solve(
        chain, goal, goal_rot, q, iterations, rotation_weight=rotation_weight
    )
    solved = jax.vmap(solve)(starts)
    pos, rot = jax.vmap(lambda q: ik.forward(chain, q))(solved)
    angle = jax.vmap(angle_between, in_axes=(0, None))(rot, goal_rot)
    cost = jnp.sum((pos - goal) ** 2, axis=-1) + (rotation_weight * angle) ** 2
    return solved[jnp.argmin(cost)]


def contact_check(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    qpos,
    mocap_pos,
    mocap_quat,
    groups: np.ndarray,
    contact_distance: float,
) -> tuple[bool, float]:
    """Whether every success group ((G, 15) bool, empty rows skipped) has a phalanx within
    ``contact_distance`` of the partner in this configuration, and how deep (m, >= 0) the
    deepest agent-target contact presses in (``model``: ``physics.native_model``)."""
    touching = phalanx_distances(model, data, qpos, mocap_pos, mocap_quat) < contact_distance
    success = all(touching[g].any() for g in groups.astype(bool) if g.any())
    any_found, closest = data.sensordata[scene.SENSOR_LAYOUT.closest]
    return bool(success), float(max(-closest, 0.0)) if any_found > 0 else 0.0


def carried_contacts(
    run_dir: str,
    max_angle: float,
    step: float,
    episodes: int,
    seed: int,
    restarts: int,
    iterations: int,
    rotation_weight: float,
    depth_margin: float,
) -> dict:
    """Per yaw x pitch cell, the share of the policy's nominal successes whose contact
    configuration, carried with the turned target, meets the success condition (see the
    module docstring, ``--carry``)."""
    loaded = policies.load_policy(run_dir, eval_envs=episodes)
    env = env_lib.scoring_env(loaded.single.config)
    keys = jax.random.split(jax.random.PRNGKey(seed), episodes)  # the sweep's episodes
    identity = np.tile(np.array([1.0, 0.0, 0.0, 0.0], np.float32), (episodes, 1))
    trajectory = rollouts.rollout(env, loaded.act, keys, reset=robustness.sweep_reset(env, False),
                                  reset_args=(identity, np.zeros(episodes, np.float32)))  # fmt: skip
    final = trajectory["qpos"][-1]  # (n, nq), the static partner's episodes
    won = np.flatnonzero(trajectory["success"][-1] > 0.5)
    if won.size == 0:
        raise ValueError(f"{run_dir}: no episode ends in success at the nominal pose")
    # MuJoCo's joint limits are soft: the policies' own states press past them (by up to
    # ~0.02 rad); the IK may go as far, or it could not even keep the nominal pose.
    joints = final[won][:, env.chain.qpos_adr]
    chain = dataclasses.replace(env.chain, lower=np.minimum(env.chain.lower, joints.min(axis=0)),
                                upper=np.maximum(env.chain.upper, joints.max(axis=0)))  # fmt: skip
    reset = jax.jit(jax.vmap(env.reset_with))
    nominal = reset(keys, identity).info["episode"]
    palm_pos, palm_rot = jax.vmap(lambda q: ik.forward(chain, q))(
        jnp.asarray(final[:, chain.qpos_adr])
    )
    rel_pos, rel_rot = jax.vmap(relative_pose)(
        palm_pos, palm_rot, nominal.target_pos, nominal.target_rot
    )
    model = physics.native_model(env.mj_model, env.config.contact_distance)
    data = mujoco.MjData(model)
    groups = np.asarray(env.params.success_groups[0])
    depth_nominal = [contact_check(model, data, final[i], trajectory["mocap_pos"][-1, i],
                                   trajectory["mocap_quat"][-1, i], groups,
                                   env.config.contact_distance)[1] for i in won]  # fmt: skip
    solve = jax.jit(
        jax.vmap(lambda *a: carried_arm(chain, *a, restarts, iterations, rotation_weight))
    )
    angles = angle_grid(max_angle, step)
    # Every (episode, shape) pair: episode i's turned target, success j's contact shape.
    pair_i, pair_j = (
        x.ravel() for x in np.meshgrid(np.arange(episodes), np.arange(won.size), indexing="ij")
    )
    own = won[pair_j] == pair_i
    any_shape = np.zeros((angles.size, angles.size))
    own_shape = np.zeros((angles.size, angles.size))
    limited, misfits = np.zeros(chain.qpos_adr.size), 0
    inside_30 = _within(angles, 30)
    # Each pair's contact shape and IK start, the same in every cell: on the device once.
    shapes = (rel_pos[won][pair_j], rel_rot[won][pair_j])
    starts = jnp.asarray(final[won][pair_j][:, chain.qpos_adr])
    for r, pitch in enumerate(np.radians(angles)):  # rows: pitch, as the orientation sweep
        for c, yaw in enumerate(np.radians(angles)):
            tilt = np.tile(np.asarray(env_lib.yaw_pitch_quat(yaw, pitch)), (episodes, 1))
            turned = reset(keys, tilt)
            target = turned.info["episode"]
            key = jax.random.PRNGKey(r * 100 + c)
            arm = np.asarray(solve(*shapes, target.target_pos[pair_i], target.target_rot[pair_i],
                                   starts, jax.random.split(key, pair_i.size)))  # fmt: skip
            mocap_pos = np.asarray(turned.pipeline_state.mocap_pos)  # one copy a cell
            mocap_quat = np.asarray(turned.pipeline_state.mocap_quat)
            fits = np.zeros(pair_i.size, bool)
            for k, (i, j) in enumerate(zip(pair_i, pair_j)):
                qpos = final[won[j]].copy()
                qpos[chain.qpos_adr] = arm[k]
                ok, depth = contact_check(model, data, qpos, mocap_pos[i], mocap_quat[i], groups,
                                          env.config.contact_distance)  # fmt: skip
                fits[k] = ok and depth <= depth_nominal[j] + depth_margin
            own_shape[r, c] = fits[own].mean()
            any_shape[r, c] = fits.reshape(episodes, won.size).any(axis=1).mean()
            if inside_30[r, c]:  # which joints the misfits' best solutions leave at a limit
                at_limit = (arm <= chain.lower + 1e-3) | (arm >= chain.upper - 1e-3)
                limited += at_limit[~fits].sum(axis=0)
                misfits += int((~fits).sum())
    return {
        "task": loaded.config.env.task,
        "run_dir": run_dir,
        "angles_deg": angles.tolist(),
        "episodes": episodes,
        "nominal_successes": int(won.size),
        "restarts": restarts,
        "ik_iterations": iterations,
        "rotation_weight_m_per_rad": rotation_weight,
        "depth_margin_m": depth_margin,
        "own_shape": own_shape.tolist(),
        "any_shape": any_shape.tolist(),
        # Within +-30 deg: of the (episode, shape) pairs that do not fit, the share whose
        # best IK solution leaves each arm and wrist joint at its limit.
        "misfits_within_30_deg": misfits,
        "misfits_at_joint_limit_within_30_deg": {
            env.mj_model.joint(int(np.flatnonzero(env.mj_model.jnt_qposadr == adr)[0])).name: float(
                n / max(misfits, 1)
            )
            for adr, n in zip(chain.qpos_adr, limited)
        },
    } | {
        f"{name}_within_{a}_deg": float(grid[_within(angles, a)].mean())
        for name, grid in (("own_shape", own_shape), ("any_shape", any_shape))
        for a in (30, 45, 60)
    }


def _within(angles: np.ndarray, limit: float) -> np.ndarray:
    """(n, n) bool mask of the yaw x pitch cells with both angles within ``limit`` deg."""
    inside = np.abs(angles) <= limit + 1e-9
    return inside[:, None] & inside[None, :]


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--task", default="et", choices=list(CONTACT_POINTS))
    parser.add_argument("--mocap-source", default="optitrack", choices=MOCAP_SOURCES)
    parser.add_argument("--max-angle-deg", type=float, default=60.0)
    parser.add_argument("--angle-step-deg", type=float, default=15.0)
    parser.add_argument("--episodes", type=int, default=32, help="the sweep's episodes per cell")
    parser.add_argument("--seed", type=int, default=EVAL_SEED, help="the sweep's episode seed")
    parser.add_argument(
        "--restarts", type=int, default=8, help="random IK starts besides the start pose"
    )
    parser.add_argument("--ik-iterations", type=int, default=100)
    parser.add_argument(
        "--tolerance", type=float, default=0.01, help="m from the goal that counts as reached"
    )
    parser.add_argument(
        "--rotation-weight",
        type=float,
        default=0.0,
        help="m per radian of palm orientation error in the IK (0: position only; "
        "palm tasks: the palm turns to its demonstrated orientation at contact)",
    )
    parser.add_argument(
        "--angle-tolerance",
        type=float,
        default=10.0,
        help="deg of palm orientation miss past the nominal pose's that still "
        "counts as reached (with --rotation-weight)",
    )
    parser.add_argument(
        "--carry",
        metavar="RUN_DIR",
        help="carry this run's nominal contacts with the turned target instead "
        "(see above; --task is the run's)",
    )
    parser.add_argument(
        "--carry-rotation-weight",
        type=float,
        default=1.0,
        help="m per radian of the palm's orientation error in --carry's IK",
    )
    parser.add_argument(
        "--carry-depth",
        type=float,
        default=0.002,
        help="m deeper than at the nominal pose that --carry lets a contact press",
    )
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    if args.carry:
        record = machine.provenance("benchmarks.reachability", argv) | carried_contacts(
            args.carry,
            args.max_angle_deg,
            args.angle_step_deg,
            args.episodes,
            args.seed,
            args.restarts,
            args.ik_iterations,
            args.carry_rotation_weight,
            args.carry_depth,
        )
        print(f"{record['task']}: {record['nominal_successes']} nominal contact shapes carried")
        for name in ("own_shape", "any_shape"):
            angles = ", ".join(f"{a:g}" for a in record["angles_deg"])
            print(f"{name} (rows pitch, columns yaw {angles}):")
            for angle, row in zip(record["angles_deg"], record[name]):
                print(f"  pitch {angle:+5.0f}: " + " ".join(f"{v:4.2f}" for v in row))
            within = [record[f"{name}_within_{a}_deg"] for a in (30, 45, 60)]
            print("  within +-30 / 45 / 60 deg: " + " / ".join(f"{v:.2f}" for v in within))
        limits = record["misfits_at_joint_limit_within_30_deg"]
        print(
            f"misfits within +-30 deg ({record['misfits_within_30_deg']}) at a joint limit: "
            + ", ".join(f"{name} {share:.2f}" for name, share in limits.items())
        )
        machine.write_record(args.out, record)
        return record
    record = machine.provenance("benchmarks.reachability", argv) | reachability(
        args.task,
        args.mocap_source,
        args.max_angle_deg,
        args.angle_step_deg,
        args.episodes,
        args.seed,
        args.restarts,
        args.ik_iterations,
        args.tolerance,
        args.rotation_weight,
        args.angle_tolerance,
    )
    for name in ("reached", "median_distance_m", "median_angle_deg"):
        grid = np.asarray(record[name])
        print(
            name
            + " (rows pitch, columns yaw "
            + ", ".join(f"{a:g}" for a in record["angles_deg"])
            + "):"
        )
        for angle, row in zip(record["angles_deg"], grid):
            print(f"  pitch {angle:+5.0f}: " + " ".join(f"{v:4.2f}" for v in row))
    machine.write_record(args.out, record)
    return record


if __name__ == "__main__":
    main()

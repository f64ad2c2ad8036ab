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
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks import machine
from mjx_hands import env as env_lib
from mjx_hands import ik, scene, shadow_hand
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


def best_reach(env, chain: ik.Chain, row: int, key, tilt, restarts: int, iterations: int,
               rotation_weight: float = 0.0):
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
    solve = lambda q0: ik.solve(chain, goal, goal_rot, q0, iterations, rotation_weight=rotation_weight)
    reached, rot = jax.vmap(lambda q0: ik.forward(chain, solve(q0)))(starts)
    angle = jax.vmap(angle_between, in_axes=(0, None))(rot, goal_rot)
    return jnp.stack([jnp.linalg.norm(reached - goal, axis=-1), angle], axis=-1)


def reachability(task: str, mocap_source: str, max_angle: float, step: float, episodes: int,
                 seed: int, restarts: int, iterations: int, tolerance: float,
                 rotation_weight: float = 0.0, angle_tolerance: float = 10.0) -> dict:
    """Per yaw x pitch cell, the share of episodes whose contact point reaches its goal
    within ``tolerance`` m, with the median misses. With ``rotation_weight`` > 0 the palm
    is turned too, and an episode counts as reached where its position and angle misses
    exceed the same episode's at the nominal pose by no more than ``tolerance`` m and
    ``angle_tolerance`` degrees (the arm already misses the human's pose there)."""
    env = env_lib.HandInteractionEnv(EnvConfig(task=task, mocap_source=mocap_source, physics="native"))
    point = CONTACT_POINTS[task]
    if rotation_weight > 0 and point != "palm":
        raise ValueError(f"--rotation-weight: the palm's orientation is asked of palm tasks "
                         f"only; {task}'s contact point is {point}")
    chain = ik.make_chain(env.mj_model, scene.AGENT + POINT_SITES[point])
    row = shadow_hand.HAND_POINTS.index(point)
    angles = angle_grid(max_angle, step)
    yaw, pitch = np.meshgrid(np.radians(angles), np.radians(angles))  # rows: pitch
    tilts = jax.vmap(env_lib.yaw_pitch_quat)(jnp.asarray(yaw.ravel()), jnp.asarray(pitch.ravel()))
    keys = jax.random.split(jax.random.PRNGKey(seed), episodes)  # the sweep's episodes
    per_cell = jax.jit(jax.vmap(lambda tilt: jax.vmap(
        lambda k: best_reach(env, chain, row, k, tilt, restarts, iterations, rotation_weight))(keys)))
    with jax.default_matmul_precision("highest"):
        misses = np.asarray(per_cell(tilts))  # (cells, episodes, starts, 2)
    # The best start per episode: by the IK's own objective (metres per radian).
    cost = misses[..., 0] ** 2 + (rotation_weight * misses[..., 1]) ** 2
    best = np.take_along_axis(misses, cost.argmin(axis=-1)[..., None, None], axis=2)[:, :, 0]
    distance, angle = best[..., 0], np.degrees(best[..., 1])  # (cells, episodes)
    shape = (angles.size, angles.size)
    if rotation_weight > 0:  # no worse than the same episode at the nominal pose
        nominal = angles.size * (angles.size // 2) + angles.size // 2  # yaw = pitch = 0
        reached = (distance <= distance[nominal] + tolerance) & (angle <= angle[nominal] + angle_tolerance)
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


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--task", default="et", choices=list(CONTACT_POINTS))
    parser.add_argument("--mocap-source", default="optitrack", choices=MOCAP_SOURCES)
    parser.add_argument("--max-angle-deg", type=float, default=60.0)
    parser.add_argument("--angle-step-deg", type=float, default=15.0)
    parser.add_argument("--episodes", type=int, default=32, help="the sweep's episodes per cell")
    parser.add_argument("--seed", type=int, default=EVAL_SEED, help="the sweep's episode seed")
    parser.add_argument("--restarts", type=int, default=8, help="random IK starts besides the start pose")
    parser.add_argument("--ik-iterations", type=int, default=100)
    parser.add_argument("--tolerance", type=float, default=0.01, help="m from the goal that counts as reached")
    parser.add_argument("--rotation-weight", type=float, default=0.0,
                        help="m per radian of palm orientation error in the IK (0: position only; "
                             "palm tasks: the palm turns to its demonstrated orientation at contact)")
    parser.add_argument("--angle-tolerance", type=float, default=10.0,
                        help="deg of palm orientation miss past the nominal pose's that still "
                             "counts as reached (with --rotation-weight)")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    record = machine.provenance("benchmarks.reachability", argv) | reachability(
        args.task, args.mocap_source, args.max_angle_deg, args.angle_step_deg, args.episodes,
        args.seed, args.restarts, args.ik_iterations, args.tolerance, args.rotation_weight,
        args.angle_tolerance)
    for name in ("reached", "median_distance_m", "median_angle_deg"):
        grid = np.asarray(record[name])
        print(name + " (rows pitch, columns yaw " + ", ".join(f"{a:g}" for a in record["angles_deg"]) + "):")
        for angle, row in zip(record["angles_deg"], grid):
            print(f"  pitch {angle:+5.0f}: " + " ".join(f"{v:4.2f}" for v in row))
    machine.write_record(args.out, record)
    return record


if __name__ == "__main__":
    main()

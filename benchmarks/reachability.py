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
do not forbid it. Kinematics only: collisions between the hands are not checked, and the
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


def best_reach(env, chain: ik.Chain, row: int, key, tilt, restarts: int, iterations: int):
    """(starts,) distances (m) from the goal of hand point ``row`` after IK from the
    episode's start pose and ``restarts`` uniform random poses, for one episode."""
    state = env.reset_with(key, tilt)
    goal = state.info["episode"].goal_points[row]
    lower, upper = jnp.asarray(chain.lower), jnp.asarray(chain.upper)
    starts = jax.random.uniform(
        jax.random.fold_in(key, 7), (restarts, lower.shape[0]), minval=lower, maxval=upper
    )
    starts = jnp.concatenate([state.pipeline_state.qpos[chain.qpos_adr][None], starts])
    solve = lambda q0: ik.solve(chain, goal, jnp.eye(3), q0, iterations, rotation_weight=0.0)
    reached = jax.vmap(lambda q0: ik.forward(chain, solve(q0))[0])(starts)
    return jnp.linalg.norm(reached - goal, axis=-1)


def reachability(task: str, mocap_source: str, max_angle: float, step: float, episodes: int,
                 seed: int, restarts: int, iterations: int, tolerance: float) -> dict:
    env = env_lib.HandInteractionEnv(EnvConfig(task=task, mocap_source=mocap_source, physics="native"))
    point = CONTACT_POINTS[task]
    chain = ik.make_chain(env.mj_model, scene.AGENT + POINT_SITES[point])
    row = shadow_hand.HAND_POINTS.index(point)
    angles = angle_grid(max_angle, step)
    yaw, pitch = np.meshgrid(np.radians(angles), np.radians(angles))  # rows: pitch
    tilts = jax.vmap(env_lib.yaw_pitch_quat)(jnp.asarray(yaw.ravel()), jnp.asarray(pitch.ravel()))
    keys = jax.random.split(jax.random.PRNGKey(seed), episodes)  # the sweep's episodes
    per_cell = jax.jit(jax.vmap(lambda tilt: jax.vmap(
        lambda k: best_reach(env, chain, row, k, tilt, restarts, iterations))(keys)))
    with jax.default_matmul_precision("highest"):
        distance = np.asarray(per_cell(tilts)).min(axis=-1)  # (cells, episodes): best start
    shape = (angles.size, angles.size)
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
        "reached": (distance <= tolerance).mean(axis=1).reshape(shape).tolist(),
        "median_distance_m": np.median(distance, axis=1).reshape(shape).tolist(),
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
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    record = machine.provenance("benchmarks.reachability", argv) | reachability(args.task, args.mocap_source, args.max_angle_deg, args.angle_step_deg,
                     args.episodes, args.seed, args.restarts, args.ik_iterations, args.tolerance)
    for name in ("reached", "median_distance_m"):
        grid = np.asarray(record[name])
        print(name + " (rows pitch, columns yaw " + ", ".join(f"{a:g}" for a in record["angles_deg"]) + "):")
        for angle, row in zip(record["angles_deg"], grid):
            print(f"  pitch {angle:+5.0f}: " + " ".join(f"{v:4.2f}" for v in row))
    machine.write_record(args.out, record)
    return record


if __name__ == "__main__":
    main()

"""Follow the demonstrations with a scripted controller; report the contacts they make.

    python -m mjx_hands.demo_replay --task handshake [--episodes 32] [--mocap-source optitrack]

Every control step the controller solves IK for the demonstrated palm pose of the
next step (relative to the simulated target hand, as the reward's references are) and
sends it, with the demonstrated finger angles, as position set-points; past the
closest approach it holds that pose. Nothing is learned. It answers whether a task's
required contacts can be reached by doing what the human did (see
``reward_params.REQUIRED_CONTACTS``) and gives learned policies a reference.
"""

from __future__ import annotations

import argparse
import json
import sys

import jax
import jax.numpy as jnp
import numpy as np

from mjx_hands import contact_profile, ik, shadow_hand
from mjx_hands import env as env_lib
from mjx_hands.env import HandInteractionEnv


def _next_step(env: HandInteractionEnv, state) -> jax.Array:
    """Row of the demonstration's references for the next control step (held at the end)."""
    episode = state.info["episode"]
    return jnp.minimum(episode.start_step + episode.step + 1, env.params.ref_angles.shape[1] - 1)


def reference_palm(env: HandInteractionEnv, state) -> tuple[jax.Array, jax.Array]:
    """World palm position (3,) and orientation (3, 3) the demonstration has at the next
    control step of ``state``'s episode (single env)."""
    episode = state.info["episode"]
    k = _next_step(env, state)
    pos = episode.target_pos + env.params.ref_palm_pos[episode.demo, k] @ episode.target_rot.T
    rot = episode.target_rot @ env.params.ref_palm_rot[episode.demo, k]
    return pos, rot


def follower_action(env: HandInteractionEnv, state, ik_iterations: int = 10) -> jax.Array:
    """(24,) action in [-1, 1] that moves toward the demonstration's next pose (single env)."""
    demo = state.info["episode"].demo
    palm_pos, palm_rot = reference_palm(env, state)
    qpos = state.pipeline_state.qpos
    arm = ik.solve(env.chain, palm_pos, palm_rot, qpos[env.chain.qpos_adr], ik_iterations)
    target = qpos.at[env.chain.qpos_adr].set(arm)  # arm + wrist from the IK
    fingers = env.params.ref_angles[demo, _next_step(env, state), 2:]
    target = target.at[env.hand_qadr[2:]].set(fingers)
    return env.action_for(target[env.actuated_qadr])


def replay(env: HandInteractionEnv, num_episodes: int, rng: jax.Array) -> dict:
    """Run ``num_episodes`` whole episodes under the follower; a JSON-ready report."""
    reset = jax.jit(jax.vmap(env.reset))
    step = jax.jit(
        lambda state: jax.vmap(env.step)(state, jax.vmap(lambda s: follower_action(env, s))(state))
    )
    state = reset(jax.random.split(rng, num_episodes))
    contacts, episode_return = [], np.zeros(num_episodes)
    for _ in range(env.episode_length):
        state = step(state)
        # The env logs each sensor's reading (contact/<sensor>) with every step.
        contacts.append(
            np.stack([state.metrics[f"contact/{n}"] for n in shadow_hand.CONTACT_SENSORS], -1)
        )
        episode_return += np.asarray(state.reward)
    profile = contact_profile.summarize(np.stack(contacts), env.params.success_groups[0])
    return {
        "task": env.config.task,
        "demonstrations": env.demos[0].source,
        "episodes": num_episodes,
        "mean_return": float(episode_return.mean()),
    } | profile


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="handshake", choices=env_lib.TASKS)
    parser.add_argument(
        "--mocap-source", default="auto", choices=("auto", "optitrack", "synthetic")
    )
    parser.add_argument("--mocap", default=None, help="folder of the demonstrations")
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="also write the report here (JSON)")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes must be at least 1, got {args.episodes}")
    try:
        env = HandInteractionEnv(
            env_lib.EnvConfig(task=args.task, mocap_source=args.mocap_source, mocap=args.mocap)
        )
    except (ValueError, FileNotFoundError) as err:
        raise SystemExit(f"error: {err}") from err
    report = replay(env, args.episodes, jax.random.PRNGKey(args.seed))
    print(
        f"{report['task']} ({report['demonstrations']} demonstrations), {args.episodes} episodes: "
        f"success {report['success']:.2f}, mean return {report['mean_return']:.1f}"
    )
    print("episodes by required sensors touching at once:", report["episodes_by_required_at_once"])
    for name, share in report["touched"].items():
        mark = "required" if name in report["required"] else ""
        print(f"  {name:12s} touched in {share:4.0%} of episodes  {mark}")
    if args.out:
        with open(args.out, "w") as f:
            json.dump(report, f, indent=1)
    return report


if __name__ == "__main__":
    main(sys.argv[1:])

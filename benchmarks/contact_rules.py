"""The two contact rules side by side on the same episodes: the project's proximity rule
(a phalanx's collision geom within 2 mm of the other hand) and the paper profile's touch
sensors (normal force in the authors' palmar box sites), read from one native rollout.

    python -m benchmarks.contact_rules --episodes 64 --out benchmarks/results_contact_rules.json

Episodes follow the demonstration (``mjx_hands.demo_replay``'s scripted follower) and,
in a second set, do the same while closing the fingers by ``--close`` of their action
range from the episode's middle on: contact-rich episodes with no trained policy needed.
Reported per task and controller: each sensor's share of steps in contact under either
rule, the share of (step, sensor) readings on which the rules agree, and success at the
end of the episode under either rule. Native physics, the project's environment
otherwise (its target box and starts), the authors' recordings when present.
"""

from __future__ import annotations

import argparse
import json
import sys

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks import machine
from mjx_hands import demo_replay, rewards, shadow_hand
from mjx_hands import env as env_lib


def closing_follower(env: env_lib.HandInteractionEnv, close: float):
    """The demonstration follower that closes every finger by ``close`` (action units)
    from the episode's middle on: single ``State`` -> action (24,). Contact-rich episodes
    without a trained policy."""
    fingers = np.zeros(env.action_size, np.float32)
    fingers[len(shadow_hand.ARM_JOINTS) + 2 :] = close  # every finger channel, not the wrist

    def act(state):
        action = demo_replay.follower_action(env, state)
        late = state.info["episode"].step >= env.episode_length // 2
        return jnp.clip(action + jnp.where(late, jnp.asarray(fingers), 0.0), -1.0, 1.0)

    return act


def rollout(env: env_lib.HandInteractionEnv, episodes: int, close: float, seed: int) -> dict:
    """Both rules' readings over ``episodes`` follower episodes; (T, N, 15) arrays."""
    act = closing_follower(env, close)

    def step(state):
        state = jax.vmap(env.step)(state, jax.vmap(act)(state))
        readings = jax.vmap(env.physics.readings)(state.pipeline_state)
        return state, readings.contacts, readings.touch

    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(seed), episodes))
    step = jax.jit(step)
    proximity, touch = [], []
    for _ in range(env.episode_length):
        state, c, t = step(state)
        proximity.append(np.asarray(c))
        touch.append(np.asarray(t))
    return {"proximity": np.stack(proximity), "touch": np.stack(touch)}


def compare(env: env_lib.HandInteractionEnv, readings: dict) -> dict:
    """Per-sensor step shares, agreement and success at the end under both rules."""
    groups = np.asarray(env.params.success_groups[0])
    out = {}
    for rule, x in readings.items():
        out[rule] = {
            "step_share": {
                n: float(x[..., i].mean()) for i, n in enumerate(shadow_hand.CONTACT_SENSORS)
            },
            "success_end": float(np.mean(rewards.success(jnp.asarray(x[-1]), groups))),
            "success_some_step": float(
                np.mean(np.any(np.asarray(rewards.success(jnp.asarray(x), groups)), axis=0))
            ),
        }
    p, t = readings["proximity"], readings["touch"]
    out["agreement"] = float(np.mean(p == t))
    out["touch_given_proximity"] = float((p * t).sum() / max(p.sum(), 1))
    out["proximity_given_touch"] = float((p * t).sum() / max(t.sum(), 1))
    return out


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", default=list(env_lib.TASKS), choices=env_lib.TASKS)
    parser.add_argument("--episodes", type=int, default=64)
    parser.add_argument("--close", type=float, default=0.5, help="finger closing, action units")
    parser.add_argument(
        "--mocap-source", default="auto", choices=("auto", "optitrack", "synthetic")
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="write the results here (JSON)")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes must be at least 1, got {args.episodes}")
    record = {"machine": machine.describe(), "args": vars(args), "tasks": {}}
    for task in args.tasks:
        env = env_lib.HandInteractionEnv(
            env_lib.EnvConfig(task=task, mocap_source=args.mocap_source, physics="native")
        )
        record["tasks"][task] = {"demonstrations": env.demos[0].source}
        for name, close in (("follower", 0.0), ("follower_closing", args.close)):
            result = compare(env, rollout(env, args.episodes, close, args.seed))
            record["tasks"][task][name] = result
            shares = ", ".join(
                f"{n} {result['proximity']['step_share'][n]:.3f}/{result['touch']['step_share'][n]:.3f}"
                for n in shadow_hand.CONTACT_SENSORS
                if result["proximity"]["step_share"][n] or result["touch"]["step_share"][n]
            )
            print(
                f"{task} {name}: agreement {result['agreement']:.4f}, success at the end "
                f"proximity {result['proximity']['success_end']:.2f} / touch "
                f"{result['touch']['success_end']:.2f}; step shares proximity/touch: {shares}"
            )
    if args.out:
        with open(args.out, "w") as f:
            json.dump(record, f, indent=1)
    return record


if __name__ == "__main__":
    main(sys.argv[1:])

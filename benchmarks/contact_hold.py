"""How policies hold contact with a moving partner: per run and target speed, the share of
steps in contact after the first contact, how often contact starts or ends, and success
at the end.

    python -m benchmarks.contact_hold LABEL=RUN_DIR [LABEL=RUN_DIR ...] \
        --out benchmarks/partners/contact_hold_handclap.json

Every policy is scored as ``mjx_hands.robustness``'s motion sweep scores it (against the
static partner of its task, carried at each ``--speeds`` in a random direction that
turns every 0.5 s, within 10 cm of its nominal place; the same episodes of evaluate's
seed for every policy and speed). "In contact" is the task's success condition (every
required sensor group touching at once) at a control step. A policy that reaches
contact and holds it has one change (the start of contact) and a share near 1; one that
touches and lets go, again and again, has many.

``--lead N ...`` also scores each policy with a privileged feed-forward beside it: every
step the policy's arm and wrist set-points move by the joint displacement (IK) that
carries the palm as far as the partner will move in N control steps at its true
velocity, which nothing learned observes (a turn of the partner stays unforeseen; 0:
the policy alone, through the same code). Where even that does not hold contact,
prediction is not what the policies lack.

``--gaps`` also says how near the misses are: after every step, each of the task's
success groups' nearest sensed phalanx's distance to the partner (negative: pressed into
it), recomputed by native MuJoCo from the recorded poses with the pairs listed from
``GAP_LISTING`` apart, and the largest over the groups (the one that decides success):
quantiles at the last step and the share of the steps from the 10th within 2, 5 and 10 mm.
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from benchmarks import machine
from mjx_hands import env as env_lib
from mjx_hands import ik, physics, policies, robustness, rollouts, scene
from mjx_hands import shadow_hand as sh

GAP_LISTING = 0.03
"""Metres apart from which ``--gaps`` lists a phalanx's pairs (beyond: no distance)."""

GAP_WITHIN = (0.002, 0.005, 0.01)
"""Distances (m) whose share of steps ``--gaps`` reports."""


def hold_statistics(success: np.ndarray) -> dict[str, float]:
    """Statistics of a (T, n) bool array of per-step success over n episodes."""
    reached = success.any(axis=0)
    first = success.argmax(axis=0)
    after = [success[f:, i].mean() for i, f in enumerate(first) if reached[i]]
    changes = (np.diff(success.astype(np.int8), axis=0) != 0).sum(axis=0)
    return {
        "success_final": float(success[-1].mean()),
        "success_some_step": float(reached.mean()),
        "first_contact_step_median": float(np.median(first[reached])) if reached.any() else None,
        "share_in_contact_after_first": float(np.mean(after)) if after else None,
        "contact_changes_median": float(np.median(changes)),
        "share_in_contact_last_10_steps": float(success[-10:].mean()),
    }


def phalanx_distances(model, data, qpos, mocap_pos, mocap_quat) -> np.ndarray:
    """(15,) each sensed phalanx's (``CONTACT_SENSORS``) nearest distance (m) to the
    partner in this configuration, inf where it has no pair listed (``model``:
    ``physics.native_model``, whose gap sets how far pairs are listed)."""
    data.qpos[:], data.mocap_pos[:], data.mocap_quat[:] = qpos, mocap_pos, mocap_quat
    mujoco.mj_forward(model, data)
    found, dist = (
        data.sensordata[scene.SENSOR_LAYOUT.contacts].reshape(len(sh.CONTACT_SENSORS), 2).T
    )
    return np.where(found > 0, dist, np.inf)


def group_gaps(mj_model, qpos, mocap_pos, mocap_quat, groups: np.ndarray) -> np.ndarray:
    """(...,) the largest over the success ``groups`` ((G, 15) bool; empty rows skipped) of
    the group's nearest sensed phalanx's distance (m) to the partner, per recorded pose
    (qpos (..., nq), mocap_pos (..., nmocap, 3), mocap_quat (..., nmocap, 4)); inf where a
    group has no pair within ``GAP_LISTING``."""
    model = physics.native_model(mj_model, GAP_LISTING)
    data = mujoco.MjData(model)
    groups = groups[groups.any(axis=1)].astype(bool)
    lead = qpos.shape[:-1]
    flat = (qpos.reshape(-1, qpos.shape[-1]), mocap_pos.reshape(-1, *mocap_pos.shape[-2:]),
            mocap_quat.reshape(-1, *mocap_quat.shape[-2:]))  # fmt: skip
    out = np.empty(flat[0].shape[0])
    for i, (q, pos, quat) in enumerate(zip(*flat)):
        nearest = phalanx_distances(model, data, q, pos, quat)
        out[i] = max(nearest[g].min() for g in groups)
    return out.reshape(lead)


def gap_statistics(gaps: np.ndarray) -> dict[str, float]:
    """Statistics of (T, n) :func:`group_gaps` after each step (metres)."""
    last = gaps[-1]
    quantiles = np.quantile(
        np.where(np.isfinite(last), last, GAP_LISTING), [0.1, 0.25, 0.5, 0.75, 0.9]
    )
    return {f"last_step_gap_q{int(100 * q)}_m": float(v) for q, v in
            zip((0.1, 0.25, 0.5, 0.75, 0.9), quantiles)} | {
        f"share_of_steps_within_{1000 * d:g}_mm": float((gaps[10:] < d).mean()) for d in GAP_WITHIN
    }  # fmt: skip


def lead_step(env, act, lead_steps: int, ik_iterations: int = 10):
    """(state) -> state, one control step of a single env: the policy's action, its arm
    and wrist set-points moved by the joint displacement (IK) that carries the palm as far
    as the partner will move in ``lead_steps`` control steps at its true velocity."""
    chain = env.chain
    arm = np.flatnonzero(np.isin(env.actuated_qadr, chain.qpos_adr))  # arm + wrist actuators
    # Each of those actuators' joint in the chain.
    joint_of = np.array([list(chain.qpos_adr).index(env.actuated_qadr[i]) for i in arm])
    lead = jnp.float32(lead_steps * env.config.control_dt)

    def step(state):
        action = act(state.obs)
        if not lead_steps:
            return env.step(state, action)
        episode = state.info["episode"]
        joints = state.pipeline_state.qpos[chain.qpos_adr]
        palm_pos, palm_rot = ik.forward(chain, joints)
        # The same solver to both poses, so that its limits and residuals cancel.
        solve = lambda goal: ik.solve(chain, goal, palm_rot, joints, ik_iterations)
        shift = solve(palm_pos + lead * episode.target_velocity) - solve(palm_pos)
        setpoints = env.ctrl_for(action).at[arm].add(shift[joint_of])
        return env.step(state, env.action_for(setpoints))

    return step


def led_success(env, act, reset, keys, reset_args, lead_steps: int) -> np.ndarray:
    """(T, n) bool: the task's success condition per step, the policy's arm led by
    :func:`lead_step`."""
    state = jax.jit(reset)(keys, *reset_args)
    step = jax.jit(jax.vmap(lead_step(env, act, lead_steps)))
    success = []
    for _ in range(env.episode_length):
        state = step(state)
        success.append(np.asarray(state.info["success"]) > 0.5)
    return np.stack(success)


def measure(
    run_dir: str,
    speeds: list[float],
    episodes: int,
    seed: int,
    leads: list[int] = (),
    gaps: bool = False,
) -> dict:
    """{speed: hold statistics} of one run's policy (with ``gaps`` its
    :func:`gap_statistics` too), and {"lead N": {speed: ...}} of it with its arm led N
    steps ahead of the partner (``leads``)."""
    loaded = policies.load_policy(run_dir, eval_envs=episodes)
    scoring = env_lib.scoring_env(loaded.single.config)
    sweep = robustness.RobustnessArgs  # the motion sweep's own turns and box
    moving = robustness.moving_target_env(scoring, sweep.turn_period, sweep.motion_box)
    reset = robustness.sweep_reset(moving, moving=True)
    keys = rollouts.episode_keys(seed, episodes)
    tilts = np.tile(np.array([1.0, 0.0, 0.0, 0.0], np.float32), (episodes, 1))
    out, tracked = {}, {f"lead {n}": {} for n in leads}
    for speed in speeds:
        reset_args = (tilts, np.full(episodes, speed, np.float32))
        trajectory = rollouts.rollout(moving, loaded.act, keys, reset=reset, reset_args=reset_args)
        out[f"{speed:g}"] = hold_statistics(trajectory["success"] > 0.5)
        if gaps:
            groups = np.asarray(moving.params.success_groups[0])
            after = group_gaps(moving.mj_model, *(trajectory[k][1:] for k in
                               ("qpos", "mocap_pos", "mocap_quat")), groups)  # fmt: skip
            out[f"{speed:g}"] |= gap_statistics(after)
        for n in leads:
            success = led_success(moving, loaded.act, reset, keys, reset_args, n)
            tracked[f"lead {n}"][f"{speed:g}"] = hold_statistics(success)
    record = {"task": loaded.config.env.task, "run_dir": run_dir, "speeds": out}
    return record | ({"led": tracked} if leads else {})


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("runs", nargs="+", help="LABEL=RUN_DIR per policy")
    parser.add_argument("--speeds", type=float, nargs="+", default=[0.0, 0.2], help="m/s")
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--seed", type=int, default=rollouts.EVAL_SEED)
    parser.add_argument(
        "--lead", type=int, nargs="*", default=[],
        help="also score each policy with its arm led this many control steps ahead of "
        "the partner's true motion (several: one each; 0: the policy alone)",
    )  # fmt: skip
    parser.add_argument(
        "--gaps",
        action="store_true",
        help="also report how near the task's contacts are (see above)",
    )
    parser.add_argument("--out")
    args = parser.parse_args(argv)
    if any(n < 0 for n in args.lead):
        parser.error(f"--lead {args.lead}: control steps must be >= 0")
    runs = {}
    for spec in args.runs:
        label, sep, run_dir = spec.partition("=")
        if not sep or not label or not run_dir:
            parser.error(f"{spec!r}: expected LABEL=RUN_DIR")
        runs[label] = measure(run_dir, args.speeds, args.episodes, args.seed, args.lead, args.gaps)
        rows = {label: runs[label]["speeds"]} | {
            f"{label}, {lead}": by_speed for lead, by_speed in runs[label].get("led", {}).items()
        }
        for name, by_speed in rows.items():
            for speed, stats in by_speed.items():
                print(f"{name} at {speed} m/s: " + ", ".join(
                    f"{k} {v:.3g}" for k, v in stats.items() if v is not None))  # fmt: skip
    record = machine.provenance("benchmarks.contact_hold", argv) | {
        "episodes": args.episodes, "seed": args.seed, "runs": runs,
    }  # fmt: skip
    machine.write_record(args.out, record)
    return record


if __name__ == "__main__":
    main()

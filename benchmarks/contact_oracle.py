"""Whether this arm can hold a task's contact with a moving partner at all: a controller
that knows the simulator and the partner's next pose, started in contact.

    python -m benchmarks.contact_oracle RUN_DIR [--speeds 0 0.1 0.2 0.3] [--episodes 32] \
        [--aim hand|joints] [--contact-weight W] [--press-mm MM] [--turn-period S] \
        --out benchmarks/partners/contact_oracle/et.json

For each of the motion sweep's episodes (``mjx_hands.robustness``: the static partner
carried at each speed in a random direction that turns every 0.5 s, evaluate's seed), the
run's policy is first rolled out with the partner at rest; its last state, in contact,
is the start and the shape to hold. The partner then moves as the sweep moves it and the
controller carries that shape with it (``--aim hand``, the default): every control step it
asks for the rest state's palm centre and five fingertips shifted by the partner's
displacement (the environment's own point sensors), with the rest state's finger joints
and the arm and wrist joints (IK) that carry the palm as a light regulariser, and picks
the 24 set-points that bring the hand there at the end of the period. It picks them by
Gauss-Newton on native MuJoCo itself (the evaluation's physics): finite-difference
rollouts of the period from the true state, with the partner's next pose, clipped to the
actuators' ranges. So it compensates the servos' lag (every joint's set-point leads it
by about 0.15 s of its travel), the contact forces and the partner's jumps, as far as the
actuators' ranges and force limits allow. The prescient oracle is given the partner's
true next pose; the reactive one extrapolates it from the last two (a turn unforeseen),
which is what a policy could know.

Success is the task's rule at each period's end, as the environment scores it. Where the
prescient controller holds contact, a target at that speed is within the arm's physical
reach and what a policy lacks is control and foresight; where it does not, the arm cannot
hold that shape of contact (a bound only for that shape: another grip might). The policy
itself, scored on the same moving episodes from its usual start, is reported beside it.
Measured (``benchmarks/partners/contact_oracle/run.sh``): on E.T. the prescient oracle
ends at 0.2 m/s as often as the policies (about 0.8), on the clap and the handshake far
less often than they, so where it fails it bounds nothing.

``--aim joints`` carries the rest joints alone (fingers as they were, arm and wrist by
IK). It is the weaker aim, kept to show why: a contact is held by force with the wrist
pressed past its limit, which a joint goal does not reproduce (see
``benchmarks/results/partners.md`` for both aims' figures).
"""

from __future__ import annotations

import argparse

import jax
import numpy as np

from benchmarks import contact_hold, machine
from mjx_hands import env as env_lib
from mjx_hands import ik, policies, rewards, robustness, rollouts, scene
from mjx_hands import physics as physics_lib
from mjx_hands import shadow_hand as sh

FD_STEP = 1e-2
"""Set-point perturbation of the finite differences (rad, the actuators' units)."""

STEP_LENGTHS = np.array([1.0, 0.5, 0.25, 0.1])
"""Shares of the Gauss-Newton step that each iteration tries."""

DAMPING = 1e-3
"""Levenberg-Marquardt damping of the normal equations, against (d joint / d set-point)^2
of about 0.04 over one period: a joint that its set-point hardly moves (at a limit, in
contact) is not sent to the end of its range."""

VELOCITY_WEIGHT = 0.02
"""Weight of the joint velocity error (rad/s) against the position error (rad): 1 rad/s
counts as 20 mrad, about a control period's travel."""

JOINT_WEIGHT = 0.005
"""Weight (m/rad) of the joints against the hand's points in :func:`hand_residuals`: a
joint 0.1 rad off its goal counts as a point 0.5 mm off."""


IK_FUNCTIONS: dict[tuple[int, int], tuple] = {}
"""(id of a chain, iterations) -> (chain, forward, solve) of :func:`ik_functions`."""


def ik_functions(chain, iterations: int):
    """(forward, solve), jitted and vmapped over episodes, of ``chain`` (one compile per
    chain object, which holds NumPy arrays and so cannot be a cache key itself; its
    limits are data of ``solve``)."""
    key = (id(chain), iterations)
    if key in IK_FUNCTIONS and IK_FUNCTIONS[key][0] is chain:
        return IK_FUNCTIONS[key][1:]
    forward = jax.jit(jax.vmap(lambda q: ik.forward(chain, q)))
    solve = jax.jit(jax.vmap(
        lambda g, r, q, limits: ik.solve(chain, g, r, q, iterations, limits=limits),
        in_axes=(0, 0, 0, None),
    ))  # fmt: skip
    IK_FUNCTIONS[key] = (chain, forward, solve)
    return forward, solve


def carried_joints(chain, rest_joints: np.ndarray, displacement: np.ndarray, iterations=20):
    """(joints (T+1, n, n_chain), palm position error (T+1, n) metres): the arm and wrist
    joints that carry the rest palm pose (chain joints ``rest_joints`` (n, n_chain)) by the
    partner's ``displacement`` (T+1, n, 3) from its rest place, each step's IK
    warm-started at the last's, and how far their palm stays from that goal (the arm's
    reach and joint limits). A contact often presses a wrist joint a little past its
    limit: the limits are widened to admit the rest joints, which the solver, clipping to
    them, would otherwise move where the partner rests."""
    limits = (np.minimum(chain.lower, rest_joints.min(0)), np.maximum(chain.upper, rest_joints.max(0)))
    forward, solve = ik_functions(chain, iterations)
    palm_pos, palm_rot = (np.asarray(x) for x in forward(rest_joints))
    joints, out, error = rest_joints, [], []
    for shift in displacement:
        joints = np.asarray(solve(palm_pos + shift, palm_rot, joints, limits))
        out.append(joints)
        error.append(np.linalg.norm(np.asarray(forward(joints)[0]) - palm_pos - shift, axis=-1))
    return np.stack(out), np.stack(error)


def success_of(sensordata: np.ndarray, groups: np.ndarray, contact_distance: float):
    """(n,) bool: the task's success rule on (n, nsensordata) readings of the last substep,
    scored as an environment step scores them (``physics.sensor_readings``, whose
    contacts read only the sensor data, then ``rewards.success``)."""
    none = np.zeros(0, np.float32)
    state = physics_lib.NativeState(qpos=none, qvel=none, ctrl=none, mocap_pos=none,
                                    mocap_quat=none, time=none, sensordata=sensordata)  # fmt: skip
    contacts = jax.vmap(lambda d: physics_lib.sensor_readings(state.replace(sensordata=d),
                                                             contact_distance).contacts)(sensordata)  # fmt: skip
    return np.asarray(rewards.success(contacts, groups))


def joint_residuals(goal_q, goal_qd, act_adr):
    """Residuals ``(qpos, qvel, sensordata) (n, k, ...) -> (n, k, 2 nu)`` of the actuated
    joints (qpos addresses ``act_adr``) against ``goal_q`` with velocity ``goal_qd`` (n, nu)."""

    def residuals(qpos, qvel, sensordata):
        return np.concatenate(
            [qpos[..., act_adr] - goal_q[:, None], VELOCITY_WEIGHT * (qvel[..., act_adr] - goal_qd[:, None])],
            axis=-1,
        )

    return residuals


def hand_residuals(goal_points, goal_q, goal_qd, act_adr, point_weights=None):
    """Residuals ``(qpos, qvel, sensordata) (n, k, ...) -> (n, k, 18 + 2 nu)``: the palm
    centre and fingertips (``HAND_POINTS``, metres, each times its ``point_weights`` (6,),
    ones when None) against ``goal_points`` (n, 6, 3), and, ``JOINT_WEIGHT`` lighter, the
    joints against ``goal_q``/``goal_qd`` (n, nu), which only settle what the points leave
    free (24 set-points against 18 coordinates)."""
    joints = joint_residuals(goal_q, goal_qd, act_adr)
    layout = scene.SENSOR_LAYOUT
    weights = np.repeat(np.ones(len(sh.HAND_POINTS)) if point_weights is None else point_weights, 3)

    def residuals(qpos, qvel, sensordata):
        points = sensordata[..., layout.points] - goal_points.reshape(len(goal_points), 1, -1)
        return np.concatenate([weights * points, JOINT_WEIGHT * joints(qpos, qvel, sensordata)], axis=-1)

    return residuals


def choose_setpoints(physics, state, mocap, ctrl, residuals_of, lo, hi, iterations=3):
    """(n, nu) set-points that bring one control period from ``state`` ((time, qpos,
    qvel) each (n, ...)) under the partner's ``mocap`` poses to the least squares of
    ``residuals_of(qpos, qvel, sensordata)`` (each (n, k, ...) at the period's end ->
    (n, k, r)): Gauss-Newton from ``ctrl`` (n, nu) with finite-difference Jacobians,
    each step's length the best of a few (never worse than not moving: joint limits and
    contacts make the period far from linear), clipped to the ranges ``lo``/``hi`` (nu,)."""
    n, nu = ctrl.shape

    def residuals(tried):  # (n, k, nu) set-points -> (n, k, r)
        k = tried.shape[1]
        rep = lambda x: np.repeat(x[:, None], k, axis=1)
        q, qd, _, sensordata = physics.run(*(rep(x) for x in state), tried, rep(mocap[0]),
                                           rep(mocap[1]), nstep=physics.n_substeps)  # fmt: skip
        return residuals_of(*(np.asarray(x, np.float64) for x in (q, qd, sensordata)))

    for _ in range(iterations):
        # Each probe into the range: MuJoCo clamps a set-point beyond it, which would
        # show as a joint the set-point does not move.
        probe = np.where(ctrl + FD_STEP > hi, -FD_STEP, FD_STEP)  # (n, nu)
        tried = np.repeat(ctrl[:, None], nu + 1, axis=1)
        tried[:, 1:] += probe[:, None, :] * np.eye(nu)  # (n, nu + 1, nu): base, then each probe
        res = residuals(tried)
        jac = (res[:, 1:] - res[:, :1]).transpose(0, 2, 1) / probe[:, None, :]  # (n, r, nu)
        normal = jac.transpose(0, 2, 1) @ jac + DAMPING * np.eye(nu)
        step = np.linalg.solve(normal, -(jac.transpose(0, 2, 1) @ res[:, 0, :, None]))[..., 0]
        tried = np.clip(ctrl[:, None] + STEP_LENGTHS[None, :, None] * step[:, None], lo, hi)
        cost = np.square(residuals(tried)).sum(-1)  # (n, len(STEP_LENGTHS))
        best = cost.argmin(axis=1)
        better = cost[np.arange(n), best] < np.square(res[:, 0]).sum(-1)
        ctrl = np.where(better[:, None], tried[np.arange(n), best], ctrl)
    return ctrl


def seen_partner(partner: np.ndarray, prescient: bool) -> np.ndarray:
    """(T+1, ...) where the oracle expects the partner's poses ``partner`` (T+1, ...) at
    each step's end: the true ones (``prescient``), or extrapolated at constant velocity
    from the two before (a turn unforeseen; at rest before the first step)."""
    if prescient:
        return partner
    before = np.concatenate([partner[:1], partner[:-1]])  # (T+1, ...): step k-1's pose
    return np.concatenate([partner[:1], 2 * partner[:-1] - before[:-1]])


AIMS = ("hand", "joints")
"""What the oracle carries with the partner: the rest contact's palm centre and fingertips
(with its joints to settle the rest, :func:`hand_residuals`), or its joints alone (the
finger joints as they were, the arm and wrist by IK, :func:`joint_residuals`)."""


def contact_point_weights(groups: np.ndarray, weight: float) -> np.ndarray:
    """(6,) weights of ``HAND_POINTS``: ``weight`` for the fingertip of every finger with a
    phalanx in a success group (``groups`` (G, 15) over ``CONTACT_SENSORS``), 1 for the rest
    (the palm centre stands for the palm, which no contact sensor covers)."""
    fingers = {sh.CONTACT_SENSORS[i].split("_")[0] for i in np.flatnonzero(np.any(groups, axis=0))}
    return np.array([weight if point in {f"{f}tip" for f in fingers} else 1.0 for point in sh.HAND_POINTS])


def hold(env, rest: dict, moving: dict, prescient: bool = True, aim: str = "hand",
         press: float = 0.0, contact_weight: float = 1.0) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(success (T, n) bool per control step, the goal palm's reach error (T+1, n) m) of
    the oracle from the rest rollout's last state (``rest``: qpos, qvel, ctrl, sensordata,
    target_pos, mocap_pos, mocap_quat, (T+1, n, ...)) under the moving rollout's partner
    poses (``moving``: mocap_pos, mocap_quat), knowing each next pose or extrapolating it
    (:func:`seen_partner`), carrying what ``aim`` (one of ``AIMS``) names, the hand's
    points ``press`` metres further towards the partner's palm than at rest, the fingertips
    of the success groups' fingers ``contact_weight`` times the rest's weight."""
    if aim not in AIMS:
        raise ValueError(f"aim {aim!r}: expected one of {AIMS}")
    physics = env.physics
    if not hasattr(physics, "run"):
        raise ValueError(f"the oracle steps native MuJoCo; {env.config.physics!r} physics has no host rollout")
    if not np.allclose(rest["mocap_pos"][-1], moving["mocap_pos"][0], atol=1e-6):
        raise ValueError("the moving episodes do not start where the partner rests")
    chain, act_adr = env.chain, env.actuated_qadr
    joint_of = np.array([list(act_adr).index(a) for a in chain.qpos_adr])  # chain -> actuator
    dt = env.config.control_dt
    qpos, qvel, ctrl, sensordata = (
        np.asarray(rest[k][-1], np.float64) for k in ("qpos", "qvel", "ctrl", "sensordata")
    )
    partner = np.asarray(moving["mocap_pos"], np.float64)
    seen = seen_partner(partner, prescient)
    root = env.target_mocap[0]  # the partner translates as one: any of its links' shift
    shift = seen[:, :, root] - partner[:1, :, root]  # (T+1, n, 3)
    carried, reach_error = carried_joints(chain, qpos[:, chain.qpos_adr], shift)
    rest_points = sensordata[:, scene.SENSOR_LAYOUT.points].reshape(len(qpos), -1, 3)
    towards = np.asarray(rest["target_pos"][-1], np.float64) - rest_points[:, 0]  # (n, 3)
    towards /= np.linalg.norm(towards, axis=-1, keepdims=True)
    goal_points = rest_points[None] + shift[:, :, None] + press * towards[None, :, None]  # (T+1, n, 6, 3)
    goal = np.repeat(qpos[None, :, act_adr], len(partner), axis=0)  # (T+1, n, nu)
    goal[..., joint_of] = carried
    goal_vel = np.zeros_like(goal)
    goal_vel[1:] = (goal[1:] - goal[:-1]) / dt  # the velocity of the step that ends there
    lo, hi = (np.asarray(x, np.float64) for x in (env.ctrl_lo, env.ctrl_hi))
    groups = np.asarray(env.params.success_groups[0])
    quat = np.asarray(moving["mocap_quat"], np.float64)
    weights = contact_point_weights(groups, contact_weight)
    time = np.zeros(len(qpos))
    success = []
    for k in range(env.episode_length):
        if aim == "hand":
            residuals = hand_residuals(goal_points[k + 1], goal[k + 1], goal_vel[k + 1], act_adr, weights)
        else:
            residuals = joint_residuals(goal[k + 1], goal_vel[k + 1], act_adr)
        ctrl = choose_setpoints(physics, (time, qpos, qvel), (seen[k + 1], quat[k + 1]), ctrl,
                                residuals, lo, hi)  # fmt: skip
        qpos, qvel, time, sensordata = (np.asarray(x, np.float64) for x in physics.run(
            time, qpos, qvel, ctrl, partner[k + 1], quat[k + 1], nstep=physics.n_substeps))  # fmt: skip
        success.append(success_of(sensordata, groups, env.config.contact_distance))
    return np.stack(success), reach_error


def measure(run_dir: str, speeds: list[float], episodes: int, seed: int, aim: str = "hand",
            press: float = 0.0, turn_period: float | None = None, contact_weight: float = 1.0) -> dict:  # fmt: skip
    """{speed: {"oracle" / "reactive_oracle" / "policy": hold statistics}} of one run."""
    loaded = policies.load_policy(run_dir, eval_envs=episodes)
    scoring = env_lib.scoring_env(loaded.single.config)
    sweep = robustness.RobustnessArgs
    turn_period = sweep.turn_period if turn_period is None else turn_period
    moving_env = robustness.moving_target_env(scoring, turn_period, sweep.motion_box)
    reset = robustness.sweep_reset(moving_env, moving=True)
    keys = rollouts.episode_keys(seed, episodes)
    tilts = np.tile(np.array([1.0, 0.0, 0.0, 0.0], np.float32), (episodes, 1))
    extra = lambda s: {
        "qvel": s.pipeline_state.qvel, "ctrl": s.pipeline_state.ctrl,
        "sensordata": s.pipeline_state.sensordata, "target_pos": s.info["episode"].target_pos,
    }  # fmt: skip
    at = lambda v: (tilts, np.full(episodes, v, np.float32))
    rest = rollouts.rollout(moving_env, loaded.act, keys, reset, at(0.0), extra)
    held = rest["success"][-1] > 0.5  # the episodes whose start is in contact
    out = {"policy_at_rest_final": float(held.mean())}
    for speed in speeds:
        moving = rollouts.rollout(moving_env, loaded.act, keys, reset, at(speed))
        row = {"policy": contact_hold.hold_statistics(moving["success"] > 0.5)}
        for name, prescient in (("oracle", True), ("reactive_oracle", False)):
            oracle, reach_error = hold(moving_env, rest, moving, prescient, aim, press, contact_weight)
            row[name] = contact_hold.hold_statistics(oracle) | {
                "success_final_of_those_in_contact_at_rest": float(oracle[-1][held].mean()),
                "goal_palm_reach_error_q90_m": float(np.quantile(reach_error, 0.9)),
                "episodes_whose_goal_palm_stays_within_2_mm": float(np.mean(reach_error.max(0) < 0.002)),
            }  # fmt: skip
            print(f"{speed:g} m/s: {name} {oracle[-1].mean():.3f}, of those in contact at rest "
                  f"{oracle[-1][held].mean():.3f} (share of steps in contact {oracle.mean():.3f})",
                  flush=True)  # fmt: skip
        print(f"{speed:g} m/s: policy {row['policy']['success_final']:.3f}", flush=True)
        out[f"{speed:g}"] = row
    return {"task": loaded.config.env.task, "run_dir": run_dir, "aim": aim, "press_m": press,
            "turn_period": turn_period, "contact_weight": contact_weight, "speeds": out}  # fmt: skip


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("run_dir", help="a train.py run folder (its policy gives the rest contact)")
    parser.add_argument("--speeds", type=float, nargs="+", default=[0.0, 0.1, 0.2, 0.3], help="m/s")
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--seed", type=int, default=rollouts.EVAL_SEED)
    parser.add_argument("--aim", choices=AIMS, default="hand", help="what the oracle carries (see AIMS)")
    parser.add_argument("--turn-period", type=float, default=robustness.RobustnessArgs.turn_period,
                        help="seconds between the partner's turns (the motion sweep's by default)")  # fmt: skip
    parser.add_argument("--contact-weight", type=float, default=1.0,
                        help="weight of the success fingers' tips against the other points (--aim hand)")  # fmt: skip
    parser.add_argument("--press-mm", type=float, default=0.0,
                        help="carry the hand this far further towards the partner's palm than at rest")  # fmt: skip
    parser.add_argument("--out")
    args = parser.parse_args(argv)
    if any(s < 0 for s in args.speeds):
        parser.error(f"--speeds {args.speeds}: speeds must be >= 0 m/s")
    if args.turn_period <= 0:
        parser.error(f"--turn-period {args.turn_period}: expected seconds > 0")
    record = machine.provenance("benchmarks.contact_oracle", argv) | {
        "episodes": args.episodes,
        "seed": args.seed,
        "run": measure(
            args.run_dir, args.speeds, args.episodes, args.seed, args.aim, args.press_mm / 1000,
            args.turn_period, args.contact_weight,
        ),
    }
    machine.write_record(args.out, record)
    return record


if __name__ == "__main__":
    main()

"""Physics and environment throughput: MJX (batched, jitted) beside native MuJoCo.

Both run the same hand-pair model from the same randomised start states under the
same random set-point sequence, so the report gives a ratio, not only absolute
numbers: MJX physics, MJX env.step, the environment on its native physics
(``physics="native"``: C MuJoCo called from the compiled env.step) and, as the
ceiling of that, pure ``mujoco.rollout`` of the same steps. Compile time is measured
apart from run time. The JSON is rewritten after every batch size, so a run cut
short keeps what it measured.

    python -m benchmarks.throughput --batch-sizes 32,128 --out benchmarks/results_cpu.json
    python -m benchmarks.throughput --batch-sizes 256,4096,16384 --env-step-batches 4096
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx, rollout

from benchmarks import machine
from mjx_hands import env as env_lib
from mjx_hands import physics


def time_loop(step, carry, actions):
    """Seconds for ``carry = step(carry, a)`` over ``actions`` after one warm-up call."""
    carry = jax.block_until_ready(step(carry, actions[0]))
    t0 = time.perf_counter()
    for a in actions:
        carry = step(carry, a)
    jax.block_until_ready(carry)
    return carry, time.perf_counter() - t0


def device_peak_bytes() -> int | None:
    """Peak bytes allocated on the first device so far (None where the backend keeps no count)."""
    stats = jax.devices()[0].memory_stats() or {}
    return stats.get("peak_bytes_in_use")


def host_peak_rss_bytes() -> int:
    """This process's peak resident memory so far (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def native_starts(env: env_lib.HandInteractionEnv, batch: int, seed: int = 0) -> mjx.Data:
    """``batch`` start states built without compiling anything: the scene's home pose
    with 0.05 rad of joint noise, the target hand where the scene puts it, forwarded by
    native MuJoCo and copied into a batched mjx.Data. ``--quick`` uses them to skip the
    ~40 s compile of env.reset; they are not the paper's randomised starts."""
    m = env.mj_model
    rng = np.random.default_rng(seed)
    datas = []
    for _ in range(batch):
        d = mujoco.MjData(m)
        d.qpos[:] = np.clip(m.qpos0 + 0.05 * rng.standard_normal(m.nq), env.jnt_lo, env.jnt_hi)
        mujoco.mj_forward(m, d)
        datas.append(mjx.put_data(m, d))
    return jax.tree.map(lambda *xs: jnp.stack(xs), *datas)


def measure_mjx(
    env: env_lib.HandInteractionEnv,
    batch: int,
    control_steps: int,
    env_step: bool = True,
    starts: mjx.Data | None = None,
) -> dict:
    """MJX physics-only and (if ``env_step``) full env.step throughput at one batch size.

    ``starts``: batched physics states to start from instead of compiled env.reset
    episode starts (then env.step, which needs episode state, is not timed).
    """
    compile_s = {}
    if starts is None:
        benv = env_lib.BatchedEnv(env, batch)
        t0 = time.perf_counter()
        reset_c = jax.jit(benv.reset).lower(jax.random.PRNGKey(0)).compile()
        compile_s["reset"] = time.perf_counter() - t0
        state = jax.block_until_ready(reset_c(jax.random.PRNGKey(0)))
        starts = state.pipeline_state
    else:
        env_step = False
    rng = np.random.default_rng(0)
    actions = jnp.asarray(rng.uniform(-1, 1, (control_steps, batch, env.action_size)), jnp.float32)

    physics_batch = jax.jit(jax.vmap(lambda d, a: env.physics.step(d, env.ctrl_for(a))))
    t0 = time.perf_counter()
    physics_c = physics_batch.lower(starts, actions[0]).compile()
    compile_s["physics"] = time.perf_counter() - t0
    data, t_physics = time_loop(physics_c, starts, actions)
    # Untimed: the exact sequence native MuJoCo runs (the timed loop repeats action 0).
    final = starts
    for a in actions:
        final = physics_c(final, a)
    n = batch * control_steps
    result = {
        "batch": batch,
        "physics_steps_per_s": n * env.n_substeps / t_physics,
        "compile_s": compile_s,
        "finite": bool(np.all(np.isfinite(np.asarray(data.qpos)))),
    }
    if env_step:
        result["_state"] = state
        t0 = time.perf_counter()
        step_c = jax.jit(benv.step).lower(state, actions[0]).compile()
        result["compile_s"]["env_step"] = time.perf_counter() - t0
        s, t_env = time_loop(step_c, state, actions)
        result["env_control_steps_per_s"] = n / t_env
        result["env_physics_steps_per_s"] = n * env.n_substeps / t_env
        result["finite"] &= bool(np.all(np.isfinite(np.asarray(s.obs))))
    result["device_peak_bytes"] = device_peak_bytes()
    result["host_peak_rss_bytes"] = host_peak_rss_bytes()
    return result | {"_start": starts, "_actions": actions, "_qpos": np.asarray(final.qpos)}


def measure_env_step(
    env: env_lib.HandInteractionEnv, mjx_state, actions: jax.Array
) -> dict:
    """env.step control steps/s of the batch on ``env``'s physics (native MuJoCo or MuJoCo
    Warp), from the MJX episodes ``mjx_state`` (their physics state posed by it) under the
    same ``actions``."""
    batch = actions.shape[1]
    benv = env_lib.BatchedEnv(env, batch)
    d = mjx_state.pipeline_state
    t0 = time.perf_counter()
    posed = jax.jit(jax.vmap(env.physics.pose))(d.qpos, d.mocap_pos, d.mocap_quat)
    state = jax.block_until_ready(mjx_state.replace(pipeline_state=posed))
    compile_s = {"pose": time.perf_counter() - t0}
    t0 = time.perf_counter()
    step_c = jax.jit(benv.step).lower(state, actions[0]).compile()
    compile_s["env_step"] = time.perf_counter() - t0
    s, t_env = time_loop(step_c, state, actions)
    n = batch * actions.shape[0]
    return {
        "env_control_steps_per_s": n / t_env,
        "env_physics_steps_per_s": n * env.n_substeps / t_env,
        "compile_s": compile_s,
        "finite": bool(np.all(np.isfinite(np.asarray(s.obs)))),
    }


def qpos_gaps(mjx_qpos: np.ndarray, native_qpos: np.ndarray) -> dict:
    """How far MJX (float32) and native MuJoCo (float64) ended apart; qpos (B, nq) each.

    Contact-rich motion under random set-points is chaotic: a rounding difference can
    send one env's finger to the other side of a contact, so the largest gap over
    thousands of envs grows with the batch and the horizon while the typical env still
    agrees. The median and the share of envs within 1e-3 say which case it is.
    """
    per_env = np.abs(mjx_qpos - native_qpos).max(axis=-1)  # (B,)
    return {
        "max_qpos_gap_vs_native": float(per_env.max()),
        "median_qpos_gap_vs_native": float(np.median(per_env)),
        "share_envs_qpos_gap_below_1e-3": float(np.mean(per_env < 1e-3)),
    }


def measure_native(env: env_lib.HandInteractionEnv, data, actions, nthread: int) -> dict:
    """``mujoco.rollout`` on all threads from the batch ``data`` (mjx.Data) under the
    set-points ``actions`` (T, B, 24), as MJX runs them."""
    m = env.mj_model
    batch = actions.shape[1]
    d = mujoco.MjData(m)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    states = np.zeros((batch, mujoco.mj_stateSize(m, spec)))
    for i in range(batch):
        d.qpos[:] = np.asarray(data.qpos[i])
        d.qvel[:] = np.asarray(data.qvel[i])
        d.mocap_pos[:] = np.asarray(data.mocap_pos[i])
        d.mocap_quat[:] = np.asarray(data.mocap_quat[i])
        mujoco.mj_getState(m, d, states[i], spec)
    a = np.asarray(actions, np.float64)
    ctrl = env.ctrl_lo + 0.5 * (a + 1.0) * (env.ctrl_hi - env.ctrl_lo)  # (T, B, nu)
    ctrl = np.repeat(ctrl.transpose(1, 0, 2), env.n_substeps, axis=1)  # (B, T*sub, nu)
    # The target hand's pose travels with the controls: the full-physics state has no
    # mocap bodies, and a rollout without them would have nothing to touch.
    mocap = np.concatenate(
        [np.asarray(data.mocap_pos).reshape(batch, -1), np.asarray(data.mocap_quat).reshape(batch, -1)],
        axis=1,
    )
    control = np.concatenate(
        [ctrl, np.broadcast_to(mocap[:, None], (batch, ctrl.shape[1], mocap.shape[1]))], axis=2
    )
    control_spec = physics.NATIVE_CONTROL_SPEC
    datas = [mujoco.MjData(m) for _ in range(nthread)]
    with rollout.Rollout(nthread=nthread) as r:
        r.rollout(m, datas, states, control[:, :1], control_spec=control_spec)  # warm-up
        t0 = time.perf_counter()
        trajectory, _ = r.rollout(m, datas, states, control, control_spec=control_spec)
        elapsed = time.perf_counter() - t0
    return {
        "nthread": nthread,
        "physics_steps_per_s": ctrl.shape[0] * ctrl.shape[1] / elapsed,
        # Full-physics state = [time, qpos, qvel, ...]: the last step's qpos.
        "_qpos": np.asarray(trajectory)[:, -1, 1 : 1 + m.nq],
    }


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="handshake")
    parser.add_argument("--batch-sizes", default="32,128")
    parser.add_argument(
        "--env-step-batches",
        default=None,
        help="batch sizes at which env.step (physics + sensors + reward) is also timed "
        "(default: all); each one costs a compile",
    )
    parser.add_argument("--control-steps", type=int, default=10)
    parser.add_argument(
        "--quick",
        action="store_true",
        help="keep the script working, not measure: batch 2, 2 control steps, 2 threads, "
        "starts from native MuJoCo instead of env.reset, no env.step (one compile)",
    )
    parser.add_argument(
        "--no-native-env",
        action="store_true",
        help="skip env.step on native physics (timed at the env.step batches by default)",
    )
    parser.add_argument(
        "--warp",
        action="store_true",
        help="also time env.step on MuJoCo Warp at the env.step batches (the [warp] extra)",
    )
    parser.add_argument("--out", default=None, help="JSON file to write")
    args = parser.parse_args(argv)
    if args.quick:
        args.batch_sizes, args.env_step_batches, args.control_steps = "2", "", 2

    env = env_lib.make_env(args.task, mocap_source="synthetic", physics="mjx")
    native_env = None if args.no_native_env else env_lib.make_env(
        args.task, mocap_source="synthetic", physics="native"
    )
    warp_env = (
        env_lib.make_env(args.task, mocap_source="synthetic", physics="warp") if args.warp else None
    )
    nthread = min(2, os.cpu_count() or 1) if args.quick else os.cpu_count() or 1
    report = {
        "machine": machine.describe(),
        "versions": machine.versions(),
        "model": env_lib.model_sizes(env),
        "control_steps": args.control_steps,
        "results": [],
    }
    batches = [int(b) for b in args.batch_sizes.split(",")]
    env_step_batches = (
        batches if args.env_step_batches is None else
        [int(b) for b in args.env_step_batches.split(",") if b]
    )
    for batch in batches:
        starts = native_starts(env, batch) if args.quick else None
        res = measure_mjx(
            env, batch, args.control_steps, env_step=batch in env_step_batches, starts=starts
        )
        actions, mjx_state = res.pop("_actions"), res.pop("_state", None)
        if native_env is not None and mjx_state is not None:
            res["native_env"] = measure_env_step(native_env, mjx_state, actions)
        if warp_env is not None and mjx_state is not None:
            res["warp_env"] = measure_env_step(warp_env, mjx_state, actions)
            res["warp_env"]["over_mjx_env_step"] = (
                res["warp_env"]["env_control_steps_per_s"] / res["env_control_steps_per_s"]
            )
        native = measure_native(env, res.pop("_start"), actions, nthread)
        # Same starts, same set-points: the two simulators must end in nearly the same pose.
        res |= qpos_gaps(res.pop("_qpos"), native.pop("_qpos"))
        res["native"] = native
        res["mjx_over_native"] = res["physics_steps_per_s"] / native["physics_steps_per_s"]
        if "native_env" in res:
            ceiling = native["physics_steps_per_s"] / env.n_substeps  # control steps/s
            res["native_env"]["over_rollout_ceiling"] = (
                res["native_env"]["env_control_steps_per_s"] / ceiling
            )
            res["native_env"]["over_mjx_env_step"] = (
                res["native_env"]["env_control_steps_per_s"] / res["env_control_steps_per_s"]
            )
        report["results"].append(res)
        print(json.dumps(res, indent=1), flush=True)
        if args.out:
            with open(args.out, "w") as f:
                json.dump(report, f, indent=1)
    return report


if __name__ == "__main__":
    main()

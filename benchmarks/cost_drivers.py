"""Where the hand pair's MJX physics time goes, one model change at a time.

Times one control period (all substeps) of vmapped MJX physics from two sets of
states: fresh episode starts, and the environment states a training run had reached
when it saved its last checkpoint (the policy's own distribution: hands closer,
more contacts). For each variant (solver settings, contacts, MJX's contact cap) it
reports physics steps/s; from the states after one control period, active contacts
and active constraint rows; and how far the final poses lie from native MuJoCo's
(float64, no contact cap, the scene as built) from the same states and set-points.

    python -m benchmarks.cost_drivers --run-dir runs/et-cpu --out benchmarks/results_cost_cpu.json
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import time
from collections.abc import Callable
from pathlib import Path

import jax
import mujoco
import numpy as np
from mujoco import mjx

from benchmarks import machine, throughput
from mjx_hands import env as env_lib


def _iterations(n: int) -> Callable[[mujoco.MjModel], None]:
    def change(m: mujoco.MjModel) -> None:
        m.opt.iterations = n

    return change


def _ls_iterations(n: int) -> Callable[[mujoco.MjModel], None]:
    def change(m: mujoco.MjModel) -> None:
        m.opt.ls_iterations = n

    return change


def _tolerance(tol: float) -> Callable[[mujoco.MjModel], None]:
    """The solver stops once its cost improvement or gradient (scaled) falls below ``tol``
    (MuJoCo's default 1e-8 is near float32 resolution, so MJX rarely stops early)."""

    def change(m: mujoco.MjModel) -> None:
        m.opt.tolerance = tol

    return change


def _no_contacts(m: mujoco.MjModel) -> None:
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT


def _contact_cap(pairs: int, points: int) -> Callable[[mujoco.MjModel], None]:
    """MJX keeps the ``pairs`` closest geom pairs per collision-function group and at
    most ``points`` contacts (the scene's numerics; native MuJoCo has no cap)."""

    def change(m: mujoco.MjModel) -> None:
        for name, value in (("max_geom_pairs", pairs), ("max_contact_points", points)):
            m.numeric_data[m.numeric_adr[m.numeric(name).id]] = value

    return change


def _palm_capsules(m: mujoco.MjModel) -> None:
    """Each palm box becomes one capsule along its longest side (radius: its smallest
    half-extent): every agent-target pair is then capsule-capsule, one collision-function
    group instead of three (capsule-capsule, box-capsule, box-box)."""
    colliding = np.union1d(m.pair_geom1, m.pair_geom2)
    for g in colliding[m.geom_type[colliding] == mujoco.mjtGeom.mjGEOM_BOX]:
        half = m.geom_size[g].copy()
        if not np.allclose(m.geom_quat[g], [1, 0, 0, 0]) or np.argmax(half) != 2:
            raise ValueError(f"palm box {m.geom(g).name} is not aligned with its body's z axis")
        radius = half.min()
        m.geom_type[g] = mujoco.mjtGeom.mjGEOM_CAPSULE
        m.geom_size[g] = [radius, half[2] - radius, 0.0]
        m.geom_rbound[g] = half[2]


def _combined(*changes: Callable[[mujoco.MjModel], None]) -> Callable[[mujoco.MjModel], None]:
    def change(m: mujoco.MjModel) -> None:
        for c in changes:
            c(m)

    return change


VARIANTS: dict[str, Callable[[mujoco.MjModel], None] | None] = {
    "as built": None,
    "1 Newton iteration": _iterations(1),
    "2 Newton iterations": _iterations(2),
    "2 line-search iterations": _ls_iterations(2),
    "tolerance 1e-5": _tolerance(1e-5),
    "contacts disabled": _no_contacts,
    "contacts disabled + 1 Newton iteration": _combined(_no_contacts, _iterations(1)),
    "palm capsules": _palm_capsules,
    "palm capsules + 1 Newton iteration": _combined(_palm_capsules, _iterations(1)),
    "contact cap 24 pairs / 48 points": _contact_cap(24, 48),
    "contact cap 48 pairs / 96 points": _contact_cap(48, 96),
}


def variant_model(env: env_lib.HandInteractionEnv, change) -> mjx.Model:
    """The env's model with ``change`` applied to a copy (the env's own stays as it is)."""
    model = copy.deepcopy(env.mj_model)
    if change is not None:
        change(model)
    return mjx.put_model(model)


def training_states(run_dir: Path) -> tuple[env_lib.HandInteractionEnv, mjx.Data]:
    """The single env of a run and its batch of env states at the last checkpoint."""
    from mjx_hands import checkpoint, policies

    try:
        _, tree, _, single = policies.restore_run(run_dir)
    except checkpoint.CheckpointError as err:
        raise SystemExit(f"error: {err}") from err
    # (devices, envs per device, ...) -> (envs, ...)
    data = tree["env_state"].pipeline_state
    return single, jax.tree.map(lambda x: x.reshape((x.shape[0] * x.shape[1],) + x.shape[2:]), data)


def on_model(model: mjx.Model, data: mjx.Data) -> mjx.Data:
    """The physical state of a batch ``data`` in Data built for ``model``.

    MJX fixes the contact and constraint-row layout when Data is made, so a variant
    that changes them (contacts disabled) needs its own Data, not the env's.
    """
    fresh = mjx.make_data(model)

    def one(d: mjx.Data) -> mjx.Data:
        return fresh.replace(
            qpos=d.qpos, qvel=d.qvel, act=d.act, ctrl=d.ctrl, time=d.time,
            mocap_pos=d.mocap_pos, mocap_quat=d.mocap_quat, qacc_warmstart=d.qacc_warmstart,
        )

    return jax.vmap(one)(data)


def state_stats(data: mjx.Data) -> dict[str, float]:
    """Active contacts and active constraint rows per env (``data`` batched). (MJX's
    solver does not write its iteration count back to Data, so that stays unknown.)"""
    impl = data._impl
    contacts = np.asarray(impl.contact.dist < impl.contact.includemargin).sum(-1)
    rows = np.asarray(impl.efc_force != 0).sum(-1)
    return {
        "active_contacts_mean": float(contacts.mean()),
        "active_contacts_max": int(contacts.max()),
        "active_constraint_rows_mean": float(rows.mean()),
    }


def compile_physics(env, model: mjx.Model, data: mjx.Data, action: jax.Array):
    """(compiled batched control period, compile seconds). The model is closed over,
    as in the environment: passed as an argument instead, XLA cannot fold the scene's
    constants and the step ran ~3x slower on CPU (254 against 753 physics steps/s)."""
    step = jax.jit(jax.vmap(lambda d, a: env.physics.step(d, env.ctrl_for(a), model)))
    t0 = time.perf_counter()
    compiled = step.lower(data, action).compile()
    return compiled, time.perf_counter() - t0


def measure(env, step, data: mjx.Data, actions: jax.Array, native_qpos=None) -> dict:
    """Physics steps/s over ``actions`` (T, B, 24) from ``data`` (B envs), plus stats and,
    given native MuJoCo's final qpos (B, nq) from the same starts, the gaps to it."""
    stats = state_stats(jax.block_until_ready(step(data, actions[0])))
    _, seconds = throughput.time_loop(step, data, actions)
    n = actions.shape[0] * actions.shape[1] * env.n_substeps
    row = {"physics_steps_per_s": n / seconds} | stats
    if native_qpos is not None:
        final = data
        for a in actions:  # untimed: exactly the sequence native MuJoCo ran
            final = step(final, a)
        row |= throughput.qpos_gaps(np.asarray(final.qpos), native_qpos)
    return row


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run-dir", type=Path, default=None,
                        help="a training run whose last checkpoint supplies visited states")
    parser.add_argument("--task", default="handshake", help="used without --run-dir")
    parser.add_argument("--batch", type=int, default=64, help="episode starts (without a run)")
    parser.add_argument("--control-steps", type=int, default=10)
    parser.add_argument("--variants", default=",".join(VARIANTS),
                        help=f"comma-separated subset of: {', '.join(VARIANTS)}")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    unknown = [v for v in args.variants.split(",") if v not in VARIANTS]
    if unknown:
        raise SystemExit(f"unknown variants {unknown}; expected some of {list(VARIANTS)}")

    if args.run_dir is not None:
        env, visited = training_states(args.run_dir)
        state_sets = {"training states": visited}
        batch = visited.qpos.shape[0]
    else:
        env = env_lib.make_env(args.task, mocap_source="synthetic", physics="mjx")
        state_sets, batch = {}, args.batch
    starts = env_lib.BatchedEnv(env, batch).reset(jax.random.PRNGKey(0)).pipeline_state
    state_sets = {"episode starts": starts} | state_sets
    rng = np.random.default_rng(0)
    actions = jax.numpy.asarray(
        rng.uniform(-1, 1, (args.control_steps, batch, env.action_size)), np.float32
    )
    report = {
        "machine": machine.describe(),
        "versions": machine.versions(),
        "model": env_lib.model_sizes(env),
        "batch": batch,
        "control_steps": args.control_steps,
        "results": [],
    }
    # The reference: native MuJoCo (float64, no contact cap) on the scene as built.
    native = {
        name: throughput.measure_native(env, data, actions, os.cpu_count() or 1)
        for name, data in state_sets.items()
    }
    native_qpos = {name: run.pop("_qpos") for name, run in native.items()}
    report["native"] = native
    for name in args.variants.split(","):
        model = variant_model(env, VARIANTS[name])
        step = compile_s = None
        for states_name, data in state_sets.items():
            data = on_model(model, data)
            if step is None:  # every state set has the same batch: one compile per variant
                step, compile_s = compile_physics(env, model, data, actions[0])
            row = {"variant": name, "states": states_name, "compile_s": compile_s}
            row |= measure(env, step, data, actions, native_qpos[states_name])
            native_rate = native[states_name]["physics_steps_per_s"]
            row["x_native"] = row["physics_steps_per_s"] / native_rate
            report["results"].append(row)
            print(json.dumps(row), flush=True)
            if args.out:
                args.out.write_text(json.dumps(report, indent=1))
    return report


if __name__ == "__main__":
    main()

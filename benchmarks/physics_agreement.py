"""MJX (its JAX and its Warp implementation) against native MuJoCo, one control period at a
time, from the very states of contact-rich native episodes.

    python -m benchmarks.physics_agreement --impls jax warp --out benchmarks/physics_agreement/handshake.json

Episodes follow the demonstration (``mjx_hands.demo_replay``'s scripted follower) and
close the fingers from the episode's middle on (as ``benchmarks.contact_rules``): the
hands meet, press and slide. Every recorded transition (state s_t, the set-points and
target pose of period t+1) is replayed on each MJX implementation from s_t, cold solver
start as the native step has, and its joint positions after the period are compared with
the native s_{t+1}. Reported per implementation: the distribution (median, 90th
percentile, max) of the largest joint-angle difference, split by whether the native step
had an agent-target contact, and the implementation's speed on that batch (control
periods per second, after its compile). ``--impls warp`` needs ``warp-lang`` (``pip
install -e ".[warp]"``); MuJoCo Warp then runs on the CPU device when no GPU is there.

``--settings`` replays MJX's JAX implementation under other scene settings too (each
with native episodes of the same scene, since solver iterations change native MuJoCo as
well): which setting causes how much of the disagreement in contact, and at what cost.
``JAX_ENABLE_X64=1`` runs MJX in float64 (precision against the rest).

    python -m benchmarks.physics_agreement --impls jax --settings scene iterations16 \
        iterations64 caps48 --out benchmarks/physics_agreement/handshake_settings.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from benchmarks import contact_rules, machine
from mjx_hands import env as env_lib
from mjx_hands import physics, scene
from mjx_hands.env_config import EnvConfig

SETTINGS = {
    "scene": {},
    "iterations16": {"solver_iterations": 16},
    "iterations64": {"solver_iterations": 64},
    "caps48": {"max_geom_pairs": 48, "max_contact_points": 64},
    "iterations64_caps48": {
        "solver_iterations": 64,
        "max_geom_pairs": 48,
        "max_contact_points": 64,
    },
    "touching": {"force_margin": 0.0},  # contacts push from touching on, not from 2 mm
}
"""Scene settings (``SceneConfig`` fields over the scene's own) of ``--settings``."""


def add_follower_arguments(parser: argparse.ArgumentParser, episodes: int) -> None:
    """The options of the native follower episodes (task, episodes, closing, seed, data)."""
    parser.add_argument("--task", default="handshake", choices=env_lib.TASKS)
    parser.add_argument("--episodes", type=int, default=episodes)
    parser.add_argument("--close", type=float, default=0.5, help="finger closing, action units")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--mocap-source", default="synthetic", choices=["optitrack", "synthetic"])


def follower_env(args, scene_config: scene.SceneConfig):
    """The native environment the follower episodes of ``args`` run in."""
    return env_lib.HandInteractionEnv(
        EnvConfig(
            task=args.task, mocap_source=args.mocap_source, physics="native", scene=scene_config
        )
    )


def native_transitions(env, episodes: int, close: float, seed: int) -> dict[str, np.ndarray]:
    """(N, ...) arrays of every transition of ``episodes`` follower episodes on native
    physics: the state before (qpos, qvel, time), the period's set-points and mocap
    poses, the native state after, and whether it had an agent-target contact."""
    act = contact_rules.closing_follower(env, close)
    step = jax.jit(lambda s: jax.vmap(env.step)(s, jax.vmap(act)(s)))
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(seed), episodes))
    keys = ("qpos", "qvel", "time", "ctrl", "mocap_pos", "mocap_quat", "sensordata")
    frames = [{k: np.asarray(getattr(state.pipeline_state, k)) for k in keys}]
    for _ in range(env.episode_length):
        state = step(state)
        frames.append({k: np.asarray(getattr(state.pipeline_state, k)) for k in keys})
    before, after = frames[:-1], frames[1:]
    cat = lambda rows, k: np.concatenate([r[k] for r in rows])
    found = cat(after, "sensordata")[:, scene.SENSOR_LAYOUT.closest][:, 0]
    return {
        "qpos": cat(before, "qpos"),
        "qvel": cat(before, "qvel"),
        "time": cat(before, "time"),
        "ctrl": cat(after, "ctrl"),
        "mocap_pos": cat(after, "mocap_pos"),
        "mocap_quat": cat(after, "mocap_quat"),
        "qpos_after": cat(after, "qpos"),
        "contact": found > 0,
    }


TRANSITION_KEYS = ("qpos", "qvel", "time", "ctrl", "mocap_pos", "mocap_quat")
"""A transition's start, in the order the period functions take it."""


def timed_periods(period, t: dict[str, np.ndarray]):
    """(qpos after one control period (N, nq), periods per second) of ``period`` (one
    transition's start -> qpos) vmapped over every transition, timed after its compile."""
    run = jax.jit(jax.vmap(period))
    args = [jnp.asarray(t[k]) for k in TRANSITION_KEYS]
    jax.block_until_ready(run(*args))  # compile (and warm up)
    start = time.perf_counter()
    qpos = np.asarray(jax.block_until_ready(run(*args)))
    return qpos, len(t["qpos"]) / (time.perf_counter() - start)


def jax_periods(model: mujoco.MjModel, n_substeps: int, t: dict[str, np.ndarray]):
    """:func:`timed_periods` of MJX's JAX implementation of ``model`` from every
    transition's start (in the model's precision: float64 under JAX_ENABLE_X64=1)."""
    m = mjx.put_model(model)
    template = mjx.put_data(model, mujoco.MjData(model))

    def period(*start):
        given = dict(zip(TRANSITION_KEYS, start, strict=True))
        d = template.replace(**{k: v.astype(getattr(template, k).dtype) for k, v in given.items()})
        with jax.default_matmul_precision("highest"):
            d = mjx.step(m, d)  # first step outside: under x64 it settles the carry's dtypes
            d = jax.lax.fori_loop(1, n_substeps, lambda _, d: mjx.step(m, d), d)
        return d.qpos

    return timed_periods(period, t)


def warp_periods(env, t: dict[str, np.ndarray], contacts_per_world: int):
    """:func:`timed_periods` of the environment's own MuJoCo Warp physics
    (``physics.WarpPhysics``, as ``--physics warp`` trains with) from every transition's
    start, with room for ``contacts_per_world`` contacts per simulation."""
    warp = physics.WarpPhysics(
        env.mj_model,
        env.n_substeps,
        env.config.contact_distance,
        worlds=len(t["qpos"]),
        contacts_per_world=contacts_per_world,
    )

    def period(qpos, qvel, time, ctrl, mocap_pos, mocap_quat):
        state = physics.rest_state(env.mj_model, warp.actuated_qadr, qpos, mocap_pos, mocap_quat)
        return warp.step(state.replace(qvel=qvel, time=time), ctrl).qpos

    return timed_periods(period, t)


def summary(diff: np.ndarray) -> dict[str, float]:
    return {
        "n": int(diff.size),
        "median": float(np.median(diff)) if diff.size else float("nan"),
        "p90": float(np.percentile(diff, 90)) if diff.size else float("nan"),
        "max": float(diff.max()) if diff.size else float("nan"),
    }


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_follower_arguments(parser, episodes=8)
    parser.add_argument("--impls", nargs="+", default=["jax", "warp"], choices=["jax", "warp"])
    parser.add_argument(
        "--warp-contacts-per-world",
        type=int,
        default=physics.WARP_CONTACTS_PER_WORLD,
        help="contacts MuJoCo Warp keeps room for per simulation (naconmax / worlds; "
        "256 for 400 worlds overflowed)",
    )
    parser.add_argument(
        "--settings",
        nargs="+",
        default=["scene"],
        choices=list(SETTINGS),
        help="scene settings to replay MJX's JAX implementation under (Warp: the scene's)",
    )
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)

    record = {
        "machine": machine.describe(),
        "versions": machine.versions(),
        "task": args.task,
        "episodes": args.episodes,
        "close": args.close,
        "seed": args.seed,
        "warp_contacts_per_world": args.warp_contacts_per_world,
    }
    for name in args.settings:
        impls = [i for i in args.impls if name == "scene" or i == "jax"]
        result = agreement(args, SETTINGS[name], impls)
        if name == "scene":
            record |= result  # the layout of records before --settings
        else:
            record.setdefault("settings", {})[name] = result | {"scene": SETTINGS[name]}
        if args.out is not None:
            args.out.parent.mkdir(parents=True, exist_ok=True)
            args.out.write_text(json.dumps(record, indent=2))
    return record


def agreement(args, overrides: dict, impls: list[str]) -> dict:
    """Native follower episodes of the scene with ``overrides``, replayed period by period
    on each MJX implementation of ``impls``."""
    env = follower_env(args, dataclasses.replace(scene.SceneConfig(), **overrides))
    print(f"native {overrides or 'scene'}: {args.episodes} follower episodes ...", flush=True)
    t = native_transitions(env, args.episodes, args.close, args.seed)
    model = physics.native_model(env.mj_model, env.config.contact_distance)
    record = {
        "transitions": len(t["qpos"]),
        "in_contact": int(t["contact"].sum()),
        "substeps": env.n_substeps,
        "impls": {},
    }
    for impl in impls:
        print(f"MJX {impl}: {len(t['qpos'])} control periods ...", flush=True)
        try:
            if impl == "warp":
                qpos, rate = warp_periods(env, t, args.warp_contacts_per_world)
            else:
                qpos, rate = jax_periods(model, env.n_substeps, t)
        except (ImportError, RuntimeError, NotImplementedError, ValueError) as err:  # e.g. no warp
            record["impls"][impl] = {"error": f"{type(err).__name__}: {err}"}
            print(f"  {impl}: {type(err).__name__}: {err}", file=sys.stderr)
            continue
        diff = np.abs(qpos - t["qpos_after"]).max(axis=1)
        record["impls"][impl] = {
            "periods_per_second": rate,
            "contact": summary(diff[t["contact"]]),
            "free": summary(diff[~t["contact"]]),
        }
        c, f = record["impls"][impl]["contact"], record["impls"][impl]["free"]
        print(
            f"  {impl}: max |dq| after a period, free: median {f['median']:.1e}, max "
            f"{f['max']:.1e}; in contact ({c['n']}): median {c['median']:.1e}, p90 "
            f"{c['p90']:.1e}, max {c['max']:.1e} rad; {rate:,.0f} periods/s",
            flush=True,
        )
    return record


if __name__ == "__main__":
    main()

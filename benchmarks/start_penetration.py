"""How often episode starts put the two hands into each other, with and without the
retreats of ``EnvConfig.start_retreats`` (earlier along the demonstration, then
farther out along the palm line).

For each task and demonstration source it draws a batch of episode starts with the
environment's own jitted reset and checks every start with native MuJoCo (float64,
every agent-target pair, no contact cap): the deepest agent-target penetration, and
the start step used. The authors' recordings are read from ``--mocap-path``
(default ``../shared/mocap/drl_handshake``); without them only the project's own
synthetic demonstrations are checked.

    python -m benchmarks.start_penetration --out benchmarks/results_start_penetration.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax
import mujoco
import numpy as np

from benchmarks import machine
from mjx_hands import env as env_lib
from mjx_hands import mocap

DEFAULT_REAL = Path(__file__).resolve().parents[2] / "shared" / "mocap" / "drl_handshake"


def native_depths(model: mujoco.MjModel, data) -> np.ndarray:
    """Deepest agent-target penetration (m, >= 0) of each start of a batched mjx.Data."""
    poses = [np.asarray(x) for x in (data.qpos, data.mocap_pos, data.mocap_quat)]
    d = mujoco.MjData(model)
    depths = []
    for qpos, mocap_pos, mocap_quat in zip(*poses, strict=True):
        d.qpos[:], d.mocap_pos[:], d.mocap_quat[:] = qpos, mocap_pos, mocap_quat
        mujoco.mj_forward(model, d)
        depths.append(max([-c.dist for c in d.contact[: d.ncon]] + [0.0]))
    return np.array(depths)


def check(task: str, source: str, path: str | None, retreats: int, batch: int) -> dict:
    env = env_lib.make_env(
        task, num_envs=batch, mocap_source=source, mocap_path=path, start_retreats=retreats
    )
    state = jax.jit(env.reset)(jax.random.PRNGKey(0))
    depth = native_depths(env.unwrapped.mj_model, state.pipeline_state)
    start = np.asarray(state.info["episode"].start_step)
    limit = env.unwrapped.config.start_max_penetration
    return {
        "task": task,
        "source": source,
        "start_retreats": retreats,
        "starts": batch,
        "penetrating_over_limit": int((depth > limit).sum()),
        "penetrating_over_3mm": int((depth > 0.003).sum()),
        "max_depth_m": float(depth.max()),
        "median_depth_of_penetrating_m": float(np.median(depth[depth > limit]))
        if (depth > limit).any()
        else 0.0,
        "median_start_step": float(np.median(start)),
        "starts_at_step_1": int((start == 1).sum()),
    }


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", default="handshake,handclap,et")
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--mocap-path", type=Path, default=DEFAULT_REAL)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    default_retreats = env_lib.EnvConfig().start_retreats
    sources = {"synthetic": None}
    if (args.mocap_path / "handshake_interaction_t.npy").is_file():
        sources["optitrack"] = str(args.mocap_path)
    else:
        print(f"no recordings at {args.mocap_path}: synthetic demonstrations only")
    report = {
        "machine": machine.describe(),
        "versions": machine.versions(),
        "start_max_penetration_m": env_lib.EnvConfig().start_max_penetration,
        "start_backoff_steps": env_lib.EnvConfig().start_backoff_steps,
        "start_backoff_distance_m": env_lib.EnvConfig().start_backoff_distance,
        "results": [],
    }
    for task in args.tasks.split(","):
        for source, path in sources.items():
            for retreats in (0, default_retreats):
                try:
                    row = check(task, source, path, retreats, args.batch)
                except mocap.MocapError as err:
                    raise SystemExit(f"error: {err}") from err
                report["results"].append(row)
                print(json.dumps(row), flush=True)
                if args.out:
                    args.out.write_text(json.dumps(report, indent=1))
    return report


if __name__ == "__main__":
    main()

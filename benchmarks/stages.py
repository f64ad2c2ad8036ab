"""Where one batched MJX physics step of the hand pair spends its time, stage by stage.

Jits each stage of ``mjx.step`` (kinematics, collision, constraint rows, solver, ...)
on its own, vmapped over a batch of episode starts, each stage fed the previous
stage's output, and times it. A jitted call that only bumps ``Data.time`` gives the
fixed cost of calling a jitted function on a batched ``Data`` (dispatch, copies),
which every stage row includes once; the whole step, compiled as one program, pays it
once. ``--compare-xla-default`` repeats the run in a subprocess with XLA's default
CPU code generation (see ``mjx_hands/xla_flags.py``), so both land in one report.

    python -m benchmarks.stages --batch 128 --compare-xla-default \
        --out benchmarks/results_stages_cpu.json
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax
from mujoco.mjx._src import collision_driver, constraint, forward, smooth, solver

from benchmarks import machine
from mjx_hands import env as env_lib
from mjx_hands import xla_flags

# mjx.step's order (forward.fwd_position ... forward.euler); sensor stages are empty
# here (the scene defines no MuJoCo sensors) and left out.
STAGES = {
    "kinematics": smooth.kinematics,
    "com_pos": smooth.com_pos,
    "crb": smooth.crb,
    "factor_m": smooth.factor_m,
    "collision": collision_driver.collision,
    "make_constraint": constraint.make_constraint,
    "transmission": smooth.transmission,
    "fwd_velocity": forward.fwd_velocity,
    "fwd_actuation": forward.fwd_actuation,
    "fwd_acceleration": forward.fwd_acceleration,
    "solve": solver.solve,
    "euler": forward.euler,
}


def _bump_time(model, data):
    return data.replace(time=data.time + model.opt.timestep)


def time_compiled(fn, data, repeats: int) -> tuple[float, float, object]:
    """(seconds per call, compile seconds, output) of jit(vmap(fn)) on the batch ``data``."""
    t0 = time.perf_counter()
    compiled = jax.jit(jax.vmap(fn)).lower(data).compile()
    compile_s = time.perf_counter() - t0
    out = jax.block_until_ready(compiled(data))
    t0 = time.perf_counter()
    for _ in range(repeats):
        result = compiled(data)
    jax.block_until_ready(result)
    return (time.perf_counter() - t0) / repeats, compile_s, out


def measure(env: env_lib.HandInteractionEnv, batch: int, repeats: int) -> dict:
    """Per-stage and whole-step milliseconds per batched call at ``batch`` envs."""
    model = env.physics.mjx_model
    data = env_lib.BatchedEnv(env, batch).reset(jax.random.PRNGKey(0)).pipeline_state
    rows = []
    for name, fn in {"call overhead": _bump_time, **STAGES, "mjx.step (whole)": None}.items():
        stage = (lambda d: forward.step(model, d)) if fn is None else (lambda d, f=fn: f(model, d))
        seconds, compile_s, out = time_compiled(stage, data, repeats)
        rows.append({"stage": name, "ms": 1e3 * seconds, "compile_s": compile_s})
        print(json.dumps(rows[-1]), flush=True)
        if fn is not None and fn is not _bump_time:
            data = out  # the next stage sees what mjx.step would hand it
    step_ms = rows[-1]["ms"]
    return {
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "legacy_cpu_emitters": xla_flags.FLAG in os.environ.get("XLA_FLAGS", "").split(),
        "rows": rows,
        "physics_steps_per_s": batch / (step_ms / 1e3),
    }


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=128)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument(
        "--compare-xla-default",
        action="store_true",
        help="also run with XLA's default CPU code generation (a subprocess) for an A/B",
    )
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    env = env_lib.make_env("handshake", mocap_source="synthetic", physics="mjx")
    report = {
        "machine": machine.describe(),
        "versions": machine.versions(),
        "model": env_lib.model_sizes(env),
        "batch": args.batch,
        "runs": [measure(env, args.batch, args.repeats)],
    }
    if args.compare_xla_default:
        flags = os.environ.get("XLA_FLAGS", "").replace(xla_flags.FLAG, "")
        child_env = os.environ | {"XLA_FLAGS": f"{flags} --{xla_flags.FLAG_NAME}=true".strip()}
        cmd = [sys.executable, "-m", "benchmarks.stages", "--batch", str(args.batch),
               "--repeats", str(args.repeats)]
        with tempfile.TemporaryDirectory() as tmp:
            other = Path(tmp) / "default.json"
            repo = Path(__file__).parents[1]
            subprocess.run(cmd + ["--out", str(other)], env=child_env, check=True, cwd=repo)
            report["runs"] += json.loads(other.read_text())["runs"]
    if args.out:
        args.out.write_text(json.dumps(report, indent=1))
    return report


if __name__ == "__main__":
    main()

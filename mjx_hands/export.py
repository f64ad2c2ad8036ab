"""``python -m mjx_hands.export RUN_DIR --onnx OUT/policy.onnx``: a trained policy as a
folder a robot's computer runs without JAX.

The folder (``OUT``, the ONNX file's):

* ``policy.onnx``: the deterministic policy, observation normalisation inside:
  ``observation`` (B, n) float32 -> ``action`` (B, 24) in [-1, 1] (converted by
  ``jax2onnx`` from the policy's own JAX function);
* ``policy.json``: the observation's layout (names, order, sizes, units), the action's
  (actuators and set-point ranges), the environment's constants the player needs, and
  the check below;
* ``model.mjb``: the scene as native MuJoCo steps it (this MuJoCo version's binary);
* ``episodes.npz``: ``--episodes`` episodes of ``evaluate``'s seeds: start states, the
  partner's schedule (:meth:`mjx_hands.env.HandInteractionEnv.partner_schedule`), success
  groups, and the training program's own success at the end of each, for comparison;
* ``play.py``: the player (:mod:`mjx_hands.onnx_player`; NumPy, MuJoCo, onnxruntime).

The export checks itself: the ONNX policy's actions on every observation of those
episodes (rolled out by the JAX policy) must equal the JAX policy's to ``--atol``
(default 1e-5), or nothing is written.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import sys
from pathlib import Path
from typing import Annotated, Any

import jax
import mujoco
import numpy as np
import tyro

from mjx_hands import physics, policies, rollouts, scene, tasks
from mjx_hands import shadow_hand as sh

PLAYER = Path(__file__).with_name("onnx_player.py")
INPUT, OUTPUT = "observation", "action"


@dataclasses.dataclass(frozen=True)
class ExportArgs:
    """Export a run's policy to ONNX with its observation layout, scene and episodes, and
    a player that runs it in native MuJoCo without JAX."""

    run_dir: Annotated[Path, tyro.conf.Positional]
    """A run folder written by train.py (or a member of an experiment grid)."""
    onnx: Path
    """The ONNX file to write; the rest goes into its folder."""
    best: bool = False
    """Export the best-evaluated policy (best/) instead of the latest checkpoint."""
    step: int | None = None
    """Export this checkpoint's policy instead of the latest."""
    episodes: int = 64
    """Episodes to export (evaluate's seeds: the same episodes it scores)."""
    seed: int = rollouts.EVAL_SEED
    """Seed of the episodes: evaluate's --seed, whose episodes these are by default."""
    atol: float = 1e-5
    """Largest difference between the ONNX and the JAX policy's actions accepted."""


def observation_layout(single) -> list[dict[str, Any]]:
    """The parts of ``single``'s observation in order: name, size, units, meaning."""
    m = single.mj_model
    joints = [m.joint(i).name for i in range(m.njnt)]
    points = ", ".join(sh.HAND_POINTS)
    sensors = ", ".join(sh.CONTACT_SENSORS)
    if single.profile.observation == "paper":
        links = [scene.TARGET_LINKS[i] for i in single.observed_links]
        parts = [
            ("qpos", m.nq, "rad", f"agent joints: {', '.join(joints)}"),
            ("qvel_x_dt", m.nv, "rad", f"joint velocities x {single.config.control_dt} s"),
            ("target_links", 3 * len(links), "m, world", f"target hand links: {', '.join(links)}"),
            ("touch", len(sh.CONTACT_SENSORS), "0/1", f"touch sensors: {sensors}"),
        ]
    else:
        parts = [
            ("qpos", m.nq, "rad", f"agent joints: {', '.join(joints)}"),
            ("qvel_x_0.1", m.nv, "rad/s x 0.1", "joint velocities, same order"),
            ("contacts", len(sh.CONTACT_SENSORS), "0/1", f"phalanx within reach: {sensors}"),
            ("agent_points", 18, "m, world axes", f"{points} minus the target palm centre"),
            ("goal_offsets", 18, "m, world axes", "goal minus current point, per hand point"),
            ("imitation_offsets", 18, "m, world axes", "reference minus point (0 past t_min)"),
            ("target_points", 18, "m, world axes", "target palm + fingertips minus agent palm"),
            ("phase", 2, "1", "step / episode length, imitation active (0/1)"),
        ]
        if single.config.observe_target_velocity:
            parts.append(("target_velocity", 3, "m/s, world axes",
                          "observed target palm minus the last step's, over the control period"))
        if single.config.observe_recent_actions:
            k = single.config.observe_recent_actions
            meaning = f"the policy's last {k} actions, most recent first (the start pose's before)"
            parts.append(("recent_actions", k * single.action_size, "1, in [-1, 1]", meaning))
    layout = [dict(zip(("name", "size", "units", "meaning"), p)) for p in parts]
    total = sum(p["size"] for p in layout)
    if total != single.observation_size:
        raise ValueError(f"observation layout sums to {total}, the env's is {single.observation_size}")
    return layout


def episode_arrays(single, policy, keys: jax.Array) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """(episodes.npz's arrays, every observation of the JAX policy's rollout (N, n)) of
    the episodes of ``keys``."""
    state = jax.jit(jax.vmap(single.reset))(keys)
    schedule = jax.jit(jax.vmap(single.partner_schedule))(state)
    data, episode = state.pipeline_state, state.info["episode"]
    queue = episode.action_queue
    if queue is None:
        queue = np.zeros((len(keys), 0, single.action_size), np.float32)
    delay = episode.action_delay  # per episode where drawn, else the queue's length
    if delay is None:
        delay = np.full(len(keys), queue.shape[1])
    recent = episode.recent_actions
    if recent is None:
        recent = np.zeros((len(keys), 0, single.action_size), np.float32)
    arrays = {
        "time": np.asarray(data.time, np.float32),
        "qpos": np.asarray(data.qpos, np.float32),
        "qvel": np.asarray(data.qvel, np.float32),
        "ctrl": np.asarray(data.ctrl, np.float32),
        "mocap_quat": np.asarray(data.mocap_quat, np.float32),
        "action_queue": np.asarray(queue, np.float32),
        "action_delay": np.asarray(delay, np.int32),
        "recent_actions": np.asarray(recent, np.float32),
        "success_groups": np.asarray(single.params.success_groups)[np.asarray(episode.demo)],
    }
    arrays |= {f"partner/{k}": np.asarray(v, np.float32) for k, v in schedule.items()}
    trajectory = rollouts.rollout(single, policy, keys, extra=lambda s: {"obs": s.obs})
    arrays["jax_success_final"] = trajectory["success"][-1].astype(np.float32)
    observations = trajectory["obs"].reshape(-1, single.observation_size)
    return arrays, observations


def to_onnx(policy, observation_size: int, name: str):
    """The ONNX model of ``policy`` (observations (B, n) -> actions (B, act))."""
    from jax2onnx import to_onnx as convert

    return convert(
        lambda obs: policy(obs),
        [("B", observation_size)],
        model_name=name,
        input_names=[INPUT],
        output_names=[OUTPUT],
    )


def onnx_actions(path: Path, observations: np.ndarray) -> np.ndarray:
    import onnxruntime as ort

    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    return session.run(None, {INPUT: observations.astype(np.float32)})[0]


def export(args: ExportArgs, out=sys.stdout) -> dict[str, Any]:
    """Write the export folder of ``args``; returns policy.json's content."""
    import onnx

    if args.episodes < 1:
        raise ValueError(f"--episodes must be positive, got {args.episodes}")
    if args.onnx.suffix != ".onnx":
        raise ValueError(f"--onnx {args.onnx}: give a file name ending in .onnx")
    loaded = policies.load_policy(args.run_dir, args.step, args.episodes, args.best)
    single, config = loaded.single, loaded.config
    folder = args.onnx.parent
    print(f"rolling out {args.episodes} episodes of the JAX policy ...", file=out, flush=True)
    keys = rollouts.episode_keys(args.seed, args.episodes)
    arrays, observations = episode_arrays(single, loaded.act, keys)
    print("converting to ONNX ...", file=out, flush=True)
    model = to_onnx(loaded.act, single.observation_size, f"{config.env.task}_policy")
    folder.mkdir(parents=True, exist_ok=True)
    onnx.save(model, args.onnx)
    expected = np.asarray(jax.jit(loaded.act)(observations))
    error = float(np.max(np.abs(onnx_actions(args.onnx, observations) - expected)))
    if not error <= args.atol:
        args.onnx.unlink()
        raise ValueError(
            f"the ONNX policy's actions differ from the JAX policy's by {error:.2e} "
            f"(> --atol {args.atol}) on {len(observations)} observations; nothing exported"
        )
    native = physics.native_model(single.mj_model, single.config.contact_distance)
    mujoco.mj_saveModel(native, str(folder / "model.mjb"), None)
    np.savez_compressed(folder / "episodes.npz", **arrays)
    shutil.copyfile(PLAYER, folder / "play.py")
    m = single.mj_model
    layout = scene.SENSOR_LAYOUT
    record = {
        "policy_file": args.onnx.name,
        "input": INPUT,
        "output": OUTPUT,
        "observation": observation_layout(single),
        "action": {
            "size": single.action_size,
            "actuators": [m.actuator(i).name for i in range(m.nu)],
            "ctrl_low": single.ctrl_lo.tolist(),
            "ctrl_high": single.ctrl_hi.tolist(),
            "mapping": "ctrl = low + (action + 1) / 2 * (high - low), action clipped to [-1, 1]",
        },
        "environment": {
            "task": config.env.task,
            "profile": config.env.profile,
            "observation": single.profile.observation,
            "contact_rule": single.profile.contact_rule,
            "observe_target_velocity": single.config.observe_target_velocity,
            "contact_distance": single.config.contact_distance,
            "control_dt": single.config.control_dt,
            "substeps": single.n_substeps,
            "episode_length": single.episode_length,
            "action_delay": single.config.action_delay,
            "action_delay_range": single.config.action_delay_range,
            "observe_recent_actions": single.config.observe_recent_actions,
            "partner_motion": single.config.partner_motion,
            "sensordata": {
                name: [getattr(layout, name).start, getattr(layout, name).stop]
                for name in ("points", "contacts", "touch")
            },
            "success_groups": "episodes.npz success_groups (G, 15): one sensor of every group "
            "in contact at the last step",
            "required_contacts": list(tasks.spec(config.env.task).required_contacts),
        },
        "source": {
            "run_dir": str(args.run_dir),
            "checkpoint": "best" if args.best else "latest" if args.step is None else args.step,
            "epoch": loaded.epoch,
            "algo": config.algo,
        },
        "check": {
            "observations": len(observations),
            "max_abs_action_difference": error,
            "atol": args.atol,
        },
        "episodes": {"count": args.episodes, "seed": args.seed},
        "versions": {
            "mujoco": mujoco.__version__,
            "onnx_opset": max(o.version for o in model.opset_import if o.domain in ("", "ai.onnx")),
        },
    }
    (folder / "policy.json").write_text(json.dumps(record, indent=2))
    print(
        f"exported {args.onnx} (max |ONNX - JAX| {error:.1e} over {len(observations)} "
        f"observations), policy.json, model.mjb, episodes.npz ({args.episodes} episodes), "
        f"play.py; run: python {folder / 'play.py'} {folder}",
        file=out,
    )
    return record


def main(argv: list[str] | None = None) -> int:
    from mjx_hands import checkpoint

    args = tyro.cli(ExportArgs, args=argv, description=ExportArgs.__doc__)
    try:
        export(args)
    except (checkpoint.CheckpointError, ValueError, FileNotFoundError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())

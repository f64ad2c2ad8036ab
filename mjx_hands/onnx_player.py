"""Play an exported policy in native MuJoCo, closed loop, without JAX.

``python -m mjx_hands.export RUN_DIR --onnx OUT/policy.onnx`` writes this file beside the
policy as ``OUT/play.py``; it needs only NumPy, MuJoCo and onnxruntime (and imageio for
``--video``), so a robot's computer runs it as it is::

    python OUT/play.py OUT                     # success at the end over the exported episodes
    python OUT/play.py OUT --video play.mp4    # ... and a video of the first episode

The folder holds the policy (``policy.onnx``: observation (B, n) float32 -> action (B, 24)
in [-1, 1], its observation normalisation inside), the layout of observation and action
(``policy.json``), the scene as native MuJoCo steps it (``model.mjb``) and the exported
episodes (``episodes.npz``): each one's start state and, for every control step, where the
partner's hand is and what the policy observes of it -- all independent of the policy's
actions, so this player steps the physics and builds every other part of the observation
from its own readings, as the training environment does.

Inside the project this module is a template (``import mjx_hands`` starts JAX); nothing of
the project imports it.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

# MuJoCo picks its OpenGL platform when it is imported: without a display, render
# offscreen with EGL (--video) unless the user chose otherwise.
if not os.environ.get("DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco
import numpy as np
import onnxruntime as ort

F32 = np.float32


class Player:
    """An exported policy and its episodes; :meth:`play` runs one episode."""

    def __init__(self, folder: Path):
        folder = Path(folder)
        self.layout = json.loads((folder / "policy.json").read_text())
        self.model = mujoco.MjModel.from_binary_path(str(folder / "model.mjb"))
        self.data = mujoco.MjData(self.model)
        with np.load(folder / "episodes.npz") as f:
            self.episodes = {k: f[k] for k in f.files}
        self.session = ort.InferenceSession(
            str(folder / self.layout["policy_file"]), providers=["CPUExecutionProvider"]
        )
        env = self.layout["environment"]
        self.env = env
        self.ctrl_lo = np.asarray(self.layout["action"]["ctrl_low"], F32)
        self.ctrl_hi = np.asarray(self.layout["action"]["ctrl_high"], F32)
        self.sensors = {k: slice(*v) for k, v in env["sensordata"].items()}

    @property
    def num_episodes(self) -> int:
        return len(self.episodes["qpos"])

    # ------------------------------------------------------------------ physics
    def _run(self, state: dict, ctrl: np.ndarray, mocap: tuple, nstep: int, mocap_from=None):
        """``nstep`` physics steps from ``state`` (float32 time, qpos, qvel, as the
        training program keeps it between control periods) with the partner's mocap
        bodies at ``mocap`` (positions (nmocap, 3), quaternions (nmocap, 4)) or, given
        ``mocap_from``, carried there from it over the steps (``partner_motion``
        continuous), the solver started cold; returns (time, qpos, qvel, sensordata) in
        float32."""
        m, d = self.model, self.data
        d.time = float(state["time"])
        d.qpos[:] = state["qpos"]
        d.qvel[:] = state["qvel"]
        d.ctrl[:] = ctrl
        d.mocap_pos[:], d.mocap_quat[:] = mocap
        d.qacc_warmstart[:] = 0.0
        for i in range(nstep):
            if mocap_from is not None:
                d.mocap_pos[:], d.mocap_quat[:] = glide(mocap_from, mocap, (i + 1) / nstep)
            mujoco.mj_step(m, d)
        return F32(d.time), d.qpos.astype(F32), d.qvel.astype(F32), d.sensordata.astype(F32)

    def _glides(self, start: tuple, end: tuple) -> bool:
        """Whether the partner travels from ``start`` to ``end`` over a period's substeps
        (``partner_motion`` continuous, and it moved) rather than being placed."""
        moved = not (np.array_equal(start[0], end[0]) and np.array_equal(start[1], end[1]))
        return self.env.get("partner_motion", "per_step") == "continuous" and moved

    def _readings(self, sensordata: np.ndarray) -> dict[str, np.ndarray]:
        s = self.sensors
        per_geom = sensordata[s["contacts"]].reshape(-1, 2)
        proximity = (per_geom[:, 0] > 0) & (per_geom[:, 1] < self.env["contact_distance"])
        touch = sensordata[s["touch"]] > 0.0
        contacts = touch if self.env["contact_rule"] == "touch" else proximity
        return {"points": sensordata[s["points"]].reshape(-1, 3), "contacts": contacts.astype(F32)}

    # -------------------------------------------------------------- observation
    def observation(self, k: int, qpos, qvel, readings, partner: dict, recent=None) -> np.ndarray:
        """The observation (n,) float32 at control step ``k`` (``policy.json``'s layout);
        ``recent``: the policy's last actions (K, 24), most recent first, where it observes
        them."""
        at = {name: values[k] for name, values in partner.items()}
        points, contacts = readings["points"], readings["contacts"]
        if self.env["observation"] == "paper":
            parts = [qpos, F32(self.env["control_dt"]) * qvel, at["target_links"], contacts]
        else:
            active = at["imitation_active"]
            phase = np.array([k / self.env["episode_length"], active], F32)
            parts = [
                qpos,
                F32(0.1) * qvel,
                contacts,
                points - at["target_pos"],
                at["goal_points"] - points,
                (at["imitation_points"] - points) * active,
                at["target_points"] - points[0],
                phase,
            ]
            if self.env.get("observe_target_velocity"):  # observed palm minus the last step's
                seen = partner["target_pos"]
                step = seen[k] - seen[k - 1] if k > 0 else np.zeros(3, F32)
                parts.append(np.asarray(step, F32) / F32(self.env["control_dt"]))
            if self.env.get("observe_recent_actions"):
                parts.append(recent)
        return np.concatenate([np.asarray(p, F32).reshape(-1) for p in parts])

    def act(self, observation: np.ndarray) -> np.ndarray:
        (action,) = self.session.run(None, {self.layout["input"]: observation[None]})
        return np.clip(action[0], -1.0, 1.0)

    # ------------------------------------------------------------------ episode
    def play(self, index: int, frames: list | None = None) -> dict:
        """Episode ``index`` closed loop: its success at the end (every success group
        with a sensor in contact at the last step), return of nothing else; with
        ``frames`` a list, the MjData of every step is rendered into it."""
        e = {k: v[index] for k, v in self.episodes.items()}
        partner = {k[len("partner/") :]: v for k, v in e.items() if k.startswith("partner/")}
        state = {k: e[k] for k in ("time", "qpos", "qvel", "mocap_quat")}
        length, substeps = self.env["episode_length"], self.env["substeps"]
        # Exports before the recorded partner kept one orientation for the whole episode.
        turns = partner.get(
            "mocap_quat", np.broadcast_to(e["mocap_quat"], (length + 1,) + e["mocap_quat"].shape)
        )
        mocap = lambda k: (partner["mocap_pos"][k], turns[k])
        # The start's readings: the sensors of one step from the pose (its motion dropped).
        *_, sensordata = self._run(state, e["ctrl"], mocap(0), 1)
        readings = self._readings(sensordata)
        recent = list(e.get("recent_actions", ()))  # the policy's last actions, newest first
        obs = self.observation(0, e["qpos"], e["qvel"], readings, partner, recent)
        queue = list(e["action_queue"])  # actions not yet applied, oldest first (action delay)
        delay = int(e["action_delay"]) if "action_delay" in e else len(queue)
        observations, actions = [obs], []
        for k in range(1, length + 1):
            action = self.act(obs)
            applied = action
            if queue:
                applied = queue[len(queue) - delay] if delay > 0 else action
                queue = queue[1:] + [action]
            recent = ([action] + recent)[: len(recent)]
            ctrl = self.ctrl_lo + F32(0.5) * (applied + F32(1.0)) * (self.ctrl_hi - self.ctrl_lo)
            origin = mocap(k - 1) if self._glides(mocap(k - 1), mocap(k)) else None
            time, qpos, qvel, sensordata = self._run(state, ctrl, mocap(k), substeps, origin)
            if not (np.isfinite(qpos).all() and np.isfinite(qvel).all()):
                return {"success": False, "diverged": True, "steps": k}
            state = state | {"time": time, "qpos": qpos, "qvel": qvel}
            readings = self._readings(sensordata)
            obs = self.observation(k, qpos, qvel, readings, partner, recent)
            observations.append(obs)
            actions.append(action)
            if frames is not None:
                frames.append(self.data)
        groups = e["success_groups"].astype(bool)  # (G, 15)
        touching = (readings["contacts"][None, :] > 0.5) & groups
        success = bool(np.all(touching.any(axis=1) | ~groups.any(axis=1)))
        return {
            "success": success,
            "diverged": False,
            "steps": length,
            "observations": np.stack(observations),
            "actions": np.stack(actions),
        }


def glide(start: tuple, end: tuple, share: float) -> tuple[np.ndarray, np.ndarray]:
    """The mocap poses ``share`` of the way from ``start`` to ``end`` (each (positions
    (nmocap, 3), quaternions (nmocap, 4))): positions linearly, quaternions by normalised
    linear interpolation on the shorter arc; ``end``'s at 1 (``mjx_hands.physics.mocap_path``)."""
    (pos0, quat0), (pos1, quat1) = start, end
    if share >= 1.0:
        return pos1, quat1
    pos0, pos1 = np.asarray(pos0, F32), np.asarray(pos1, F32)
    quat0, quat1 = np.asarray(quat0, F32), np.asarray(quat1, F32)
    quat0 = quat0 * np.where(np.sum(quat0 * quat1, -1, keepdims=True) < 0, F32(-1), F32(1))
    quat = quat0 + F32(share) * (quat1 - quat0)
    return pos0 + F32(share) * (pos1 - pos0), quat / np.linalg.norm(quat, axis=-1, keepdims=True)


def render_video(player: Player, index: int, path: Path, camera: str, size=(480, 640)) -> None:
    """A video of episode ``index`` from the scene's ``camera`` (imageio with ffmpeg)."""
    import imageio.v2 as imageio

    renderer = mujoco.Renderer(player.model, *size)
    images = []

    class Frames(list):
        def append(self, data):
            renderer.update_scene(data, camera=camera)
            images.append(renderer.render())

    try:
        player.play(index, Frames())
    finally:
        renderer.close()
    imageio.mimwrite(path, images, fps=round(1.0 / player.env["control_dt"]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path, help="the export folder (policy.json inside)")
    parser.add_argument("--episodes", type=int, default=None, help="default: all exported")
    parser.add_argument("--video", type=Path, default=None, help="render episode 0 to this file")
    parser.add_argument("--camera", default="side", help="the scene's camera for --video")
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    args = parser.parse_args(argv)
    if not (args.folder / "policy.json").is_file():
        print(f"error: {args.folder} holds no exported policy (policy.json)", file=sys.stderr)
        return 2
    player = Player(args.folder)
    n = player.num_episodes if args.episodes is None else min(args.episodes, player.num_episodes)
    results = [player.play(i) for i in range(n)]
    success = [r["success"] for r in results]
    reference = player.episodes.get("jax_success_final")
    summary = {
        "episodes": n,
        "success_final": float(np.mean(success)),
        "diverged": int(sum(r["diverged"] for r in results)),
        "jax_imported": "jax" in sys.modules,
    }
    line = f"success at the end {summary['success_final']:.3f} over {n} episodes (native MuJoCo)"
    if reference is not None:
        same = int(np.sum(np.asarray(success) == reference[:n].astype(bool)))
        summary |= {"jax_success_final": float(np.mean(reference[:n])), "same_outcome": same}
        line += (
            f"; the training program's: {summary['jax_success_final']:.3f}, same outcome in {same}"
        )
    print(line)
    if args.video is not None:
        render_video(player, 0, args.video, args.camera)
        print(f"video: {args.video}")
    if args.json is not None:
        args.json.write_text(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())

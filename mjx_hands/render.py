"""Videos of rolled-out episodes with MuJoCo's offscreen renderer (``MUJOCO_GL=egl``
renders without a display; ``import mjx_hands`` chooses it when no display is set)."""

from __future__ import annotations

from pathlib import Path

VIDEO_KEYS = ("qpos", "mocap_pos", "mocap_quat")
"""The :func:`rollout` arrays (T+1, n, ...) that :func:`render_video` reads."""


def render_video(single, trajectory, path: Path, camera: str, width: int, height: int, fps: float):
    """Write the rendered episodes of ``trajectory`` (see :func:`rollout`) one after another."""
    import imageio.v2 as imageio
    import mujoco

    model = single.mj_model
    data = mujoco.MjData(model)
    renderer = mujoco.Renderer(model, height, width)
    try:
        with imageio.get_writer(str(path), fps=fps, codec="libx264", quality=7) as writer:
            for episode in range(trajectory["qpos"].shape[1]):
                for t in range(trajectory["qpos"].shape[0]):
                    data.qpos[:] = trajectory["qpos"][t, episode]
                    data.mocap_pos[:] = trajectory["mocap_pos"][t, episode]
                    data.mocap_quat[:] = trajectory["mocap_quat"][t, episode]
                    mujoco.mj_forward(model, data)
                    renderer.update_scene(data, camera=camera)
                    writer.append_data(renderer.render())
    finally:
        renderer.close()

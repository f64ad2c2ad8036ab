"""Rotations and rigid transforms in ``jnp`` (quaternions are ``w, x, y, z`` as in MuJoCo)."""

from __future__ import annotations

import jax.numpy as jnp


def quat_mul(a: jnp.ndarray, b: jnp.ndarray) -> jnp.ndarray:
    """Hamilton product. a, b: (..., 4) -> (..., 4)."""
    aw, ax, ay, az = jnp.moveaxis(a, -1, 0)
    bw, bx, by, bz = jnp.moveaxis(b, -1, 0)
    return jnp.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_to_mat(q: jnp.ndarray) -> jnp.ndarray:
    """Unit quaternion (..., 4) -> rotation matrix (..., 3, 3)."""
    w, x, y, z = jnp.moveaxis(q, -1, 0)
    return jnp.stack(
        [
            jnp.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            jnp.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            jnp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def axis_angle_quat(axis: jnp.ndarray, angle: jnp.ndarray) -> jnp.ndarray:
    """Rotation of ``angle`` (...) about unit ``axis`` (..., 3) -> (..., 4)."""
    half = 0.5 * angle
    return jnp.concatenate([jnp.cos(half)[..., None], jnp.sin(half)[..., None] * axis], axis=-1)


def rotation_error(r: jnp.ndarray, r_goal: jnp.ndarray) -> jnp.ndarray:
    """Small-angle rotation vector taking ``r_goal`` to ``r`` (world axes). (3,3),(3,3)->(3,)."""
    e = 0.5 * (r_goal.T @ r - r.T @ r_goal)
    return r_goal @ jnp.stack([e[2, 1], e[0, 2], e[1, 0]])

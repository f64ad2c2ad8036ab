"""Inverse kinematics that places the agent's palm at a demonstrated pose.

The arm (4 joints) and the wrist (2 joints) position and orient the palm. Their
forward kinematics is a fixed chain of rigid offsets and hinge rotations read from
the compiled model once, so the solver traces a few dozen small ``jnp`` ops instead
of a whole ``mjx.kinematics`` (cheap to compile, cheap to run inside ``reset``).
Damped least squares with joint-limit clipping converges to the closest reachable
pose when the requested one is out of reach.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from mjx_hands import spatial


@dataclasses.dataclass(frozen=True)
class Chain:
    """A serial chain of bodies from the world to an end frame (static NumPy data).

    Attributes:
      body_pos: (n_bodies, 3) body offsets in their parents.
      body_quat: (n_bodies, 4) body orientations in their parents.
      joints: per body, the tuple of chain-joint indices (into ``qpos_adr``) it carries.
      axes: (n_joints, 3) hinge axes in their bodies' frames.
      qpos_adr: (n_joints,) addresses of the chain joints in ``qpos``.
      lower, upper: (n_joints,) joint limits.
      end_pos: (3,) end point (a site) in the last body's frame.
    """

    body_pos: np.ndarray
    body_quat: np.ndarray
    joints: tuple[tuple[int, ...], ...]
    axes: np.ndarray
    qpos_adr: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    end_pos: np.ndarray


def make_chain(model: mujoco.MjModel, site: str) -> Chain:
    """Chain from the world to ``site``: every hinge on the way is a chain joint."""
    site_id = model.site(site).id
    bodies = []
    b = int(model.site_bodyid[site_id])
    while b != 0:
        bodies.append(b)
        b = int(model.body_parentid[b])
    bodies.reverse()
    joints, axes, adr, lo, hi = [], [], [], [], []
    for body in bodies:
        ids = []
        for j in range(model.body_jntadr[body], model.body_jntadr[body] + model.body_jntnum[body]):
            if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
                raise ValueError(f"IK chain supports hinges only; joint {model.joint(j).name}")
            if np.any(model.jnt_pos[j] != 0):
                raise ValueError(f"IK chain expects joints at body origins; {model.joint(j).name}")
            ids.append(len(adr))
            axes.append(model.jnt_axis[j])
            adr.append(model.jnt_qposadr[j])
            lo.append(model.jnt_range[j, 0])
            hi.append(model.jnt_range[j, 1])
        joints.append(tuple(ids))
    return Chain(
        body_pos=model.body_pos[bodies].copy(),
        body_quat=model.body_quat[bodies].copy(),
        joints=tuple(joints),
        axes=np.array(axes),
        qpos_adr=np.array(adr),
        lower=np.array(lo),
        upper=np.array(hi),
        end_pos=model.site_pos[site_id].copy(),
    )


def _hinge_rotation(axis: np.ndarray, angle: jnp.ndarray) -> jnp.ndarray:
    """Rodrigues: rotation by ``angle`` about the constant unit ``axis``. -> (3, 3)"""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + jnp.sin(angle) * k + (1.0 - jnp.cos(angle)) * (k @ k)


def forward(chain: Chain, q: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """End-frame pose for chain joint values q: (n_joints,) -> pos (3,), rot (3, 3).

    Rotation matrices rather than quaternions: matrix products are fusion boundaries
    for XLA, whereas a chain of stacked quaternion products fuses into one loop that
    recomputes its producers per element -- exponentially slow in the chain length.
    """
    pos = jnp.zeros(3)
    rot = jnp.eye(3)
    for i, ids in enumerate(chain.joints):
        pos = pos + rot @ chain.body_pos[i]
        rot = rot @ _quat_to_mat_np(chain.body_quat[i])
        for j in ids:  # MuJoCo applies a body's joints in order, each about its own axis
            rot = rot @ _hinge_rotation(chain.axes[j], q[j])
    return pos + rot @ chain.end_pos, rot


def _quat_to_mat_np(quat: np.ndarray) -> np.ndarray:
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, np.float64))
    return mat.reshape(3, 3)


def solve(
    chain: Chain,
    target_pos: jnp.ndarray,
    target_rot: jnp.ndarray,
    q0: jnp.ndarray,
    iterations: int = 30,
    rotation_weight: float = 0.2,
    damping: float = 1e-3,
    limits: tuple[jnp.ndarray, jnp.ndarray] | None = None,
) -> jnp.ndarray:
    """Damped least-squares IK with clipping to joint limits.

    Args:
      target_pos: (3,) desired end position; target_rot: (3, 3) desired orientation.
      q0: (n_joints,) initial guess.
      rotation_weight: metres per radian of orientation error in the objective
        (position matters more: goals and imitation are positional).
      limits: (lower, upper) (n_joints,) each, as data (one compile for any limits);
        the chain's own when None.
    Returns:
      (n_joints,) joint values within limits.
    """
    lower, upper = (chain.lower, chain.upper) if limits is None else limits

    def residual(q):
        pos, rot = forward(chain, q)
        return jnp.concatenate(
            [pos - target_pos, rotation_weight * spatial.rotation_error(rot, target_rot)]
        )

    def body(_, q):
        r = residual(q)
        jac = jax.jacfwd(residual)(q)
        lhs = jac.T @ jac + damping * jnp.eye(q.shape[0])
        dq = -jnp.linalg.solve(lhs, jac.T @ r)
        return jnp.clip(q + dq, lower, upper)

    q0 = jnp.clip(q0, lower, upper)
    return jax.lax.fori_loop(0, iterations, body, q0)

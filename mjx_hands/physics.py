"""The physics step behind the environment: one seam, two implementations.

Everything above the physics -- reset and its IK, rewards, observations, auto-reset,
learners -- reads :class:`Readings` and advances a state one control period through
a :class:`Physics`:

* :class:`MjxPhysics` steps MJX inside the compiled program (accelerators; thousands
  of environments). This module is the only one that reads MJX internals.
* :class:`NativePhysics` steps C MuJoCo on every core from inside the compiled program:
  a ``jax.pure_callback`` whose batched form hands the whole batch to one
  ``mujoco.rollout`` call on a persistent thread pool (CPUs, where MJX runs the hand
  pair at a tenth of native speed).
* :class:`WarpPhysics` steps MuJoCo Warp (MJX's ``impl="warp"``) inside the compiled
  program: native MuJoCo's contacts and sensors as GPU kernels (``[warp]`` extra).

All read what the scene defines once as MuJoCo sensors (``scene.SENSOR_LAYOUT``):
the palm centre and fingertip sites, the 15 phalanx contact sensors and the closest
agent-target contact. Native MuJoCo computes the sensors itself; MJX computes the same
quantities from its own kinematics and contact list (its sensor stage is switched
off: it would cost every substep, and MJX counts a contact only within the margin the
constraint uses); MuJoCo Warp computes the sensors as native MuJoCo does.

Where they differ: MJX keeps ``max_geom_pairs`` / ``max_contact_points`` contacts per
collision group in float32; native MuJoCo keeps every contact, in float64 (its state
is rounded to float32 between control periods, where it enters the JAX program), and
starts each control period's solver cold where MJX carries its warm start
(``benchmarks/native.py`` measures the difference).
"""

from __future__ import annotations

import copy
import os
import threading
from typing import Protocol

import jax
import jax.numpy as jnp
import mujoco
import mujoco.rollout
import numpy as np
from flax import struct
from mujoco import mjx

from mjx_hands import scene
from mjx_hands import shadow_hand as sh

PHYSICS = ("mjx", "native", "warp")
WARP_CONTACTS_PER_WORLD = 64
"""Contacts MuJoCo Warp keeps room for per simulation: the hand pair made up to 31 with
the hands pressed together; 256 for 400 worlds overflowed (a printed warning)."""
WARP_WORLDS = 1024
"""Simulations one Warp call steps unless told more (:meth:`WarpPhysics.reserve`)."""
WARP_SENSOR_MATCHES = 128
"""Contacts a MuJoCo Warp contact sensor considers (64 overflowed in training; the hands
pressed together made 35; it sizes buffers of ~50 kB per world)."""
WARP_CONSTRAINTS = 1024
"""Constraint rows per world MuJoCo Warp keeps room for (its ``njmax``; 64 overflowed with
the hands pressed together)."""
NATIVE_CONTROL_SPEC = int(
    mujoco.mjtState.mjSTATE_CTRL
    | mujoco.mjtState.mjSTATE_MOCAP_POS
    | mujoco.mjtState.mjSTATE_MOCAP_QUAT
)
"""What ``mujoco.rollout`` takes per step beside the state: set-points and the target
hand's mocap poses (the full-physics state has no mocap bodies)."""


@struct.dataclass
class Readings:
    """What rewards, observations and resets read from a simulation (one env)."""

    qpos: jax.Array  # (nq,) joint positions
    qvel: jax.Array  # (nv,) joint velocities
    points: jax.Array  # (6, 3) agent palm centre + fingertips, world, HAND_POINTS order
    contacts: jax.Array  # (15,) 0/1 per CONTACT_SENSORS: a phalanx geom within contact_distance
    touch: jax.Array  # (15,) 0/1 per CONTACT_SENSORS: force in the phalanx's touch site
    penetration: jax.Array  # () deepest agent-target interpenetration, metres (0: apart)
    finite: jax.Array  # () bool: the state holds no NaN or inf


class Physics(Protocol):
    """One control period of the hand-pair scene, for one environment (vmap batches it).

    ``State`` is the implementation's own pytree; it has at least ``qpos``, ``qvel``,
    ``ctrl``, ``mocap_pos`` and ``mocap_quat`` (what rendering and tools read).
    """

    name: str
    mj_model: mujoco.MjModel

    def pose(self, qpos: jax.Array, mocap_pos: jax.Array, mocap_quat: jax.Array):
        """A state at rest at ``qpos`` (nq,), set-points on the actuated joints, the
        target's mocap bodies at ``mocap_pos`` (nmocap, 3) / ``mocap_quat`` (nmocap, 4);
        its readings are those of that pose."""

    def step(self, state, ctrl: jax.Array, *, mocap_from: tuple | None = None):
        """Advance one control period with set-points ``ctrl`` (nu,). ``mocap_from``: the
        mocap poses (positions (nmocap, 3), quaternions (nmocap, 4)) the period starts
        from, carried to ``state``'s over the substeps (:func:`mocap_path`); None: the
        mocap bodies hold ``state``'s poses for the whole period."""

    def readings(self, state) -> Readings:
        """The readings of ``state`` (of the last substep's kinematics, as MuJoCo's
        sensors of an ``mj_step``)."""

    def reserve(self, worlds: int) -> None:
        """Room for ``worlds`` simulations stepped in one call (a learner's members x
        environments), before the program that steps them is traced; a no-op where the
        engine sizes nothing ahead."""


def mocap_path(start: tuple, end: tuple, n_substeps: int) -> tuple[jax.Array, jax.Array]:
    """Mocap poses at the ends of ``n_substeps`` equal substeps from ``start`` to ``end``
    (each ``(positions (nmocap, 3), quaternions (nmocap, 4))``): positions (n, nmocap, 3)
    linearly, quaternions (n, nmocap, 4) by normalised linear interpolation on the
    shorter arc; the last substep's are ``end``'s."""
    (pos0, quat0), (pos1, quat1) = start, end
    share = (jnp.arange(1, n_substeps + 1, dtype=jnp.float32) / n_substeps)[:, None, None]
    positions = pos0 + share * (pos1 - pos0)
    quat0 = quat0 * jnp.where(jnp.sum(quat0 * quat1, -1, keepdims=True) < 0, -1.0, 1.0)
    quats = quat0 + share * (quat1 - quat0)
    quats = quats / jnp.linalg.norm(quats, axis=-1, keepdims=True)
    return positions, quats.at[-1].set(quat1)


def substeps(model, data, n_substeps: int, mocap_from: tuple | None):
    """``n_substeps`` ``mjx.step`` calls of ``model`` from ``data`` (MJX or MuJoCo Warp),
    the mocap bodies carried from ``mocap_from`` to ``data``'s poses (``Physics.step``)."""
    if mocap_from is None:
        return jax.lax.fori_loop(0, n_substeps, lambda _, d: mjx.step(model, d), data)
    positions, quats = mocap_path(mocap_from, (data.mocap_pos, data.mocap_quat), n_substeps)

    def substep(d, pose):
        d = d.replace(mocap_pos=pose[0], mocap_quat=pose[1])
        return mjx.step(model, d), None

    return jax.lax.scan(substep, data, (positions, quats))[0]


def sensor_objects(m: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """From the scene's sensors: the sites of the 6 points (6,) and the contact-sensor
    index of every geom (ngeom,), -1 for geoms without one."""
    layout = scene.SENSOR_LAYOUT
    by_adr = {int(m.sensor_adr[i]): i for i in range(m.nsensor)}
    sites = [
        int(m.sensor_objid[by_adr[a]]) for a in range(layout.points.start, layout.points.stop, 3)
    ]
    sensor_of_geom = -np.ones(m.ngeom, np.int32)
    for s, adr in enumerate(range(layout.contacts.start, layout.contacts.stop, 2)):
        sensor_of_geom[m.sensor_objid[by_adr[adr]]] = s
    return np.array(sites), sensor_of_geom


def ray_hits_box(origin: jax.Array, direction: jax.Array, half: jax.Array) -> jax.Array:
    """Whether rays from ``origin`` along ``direction`` (forward only) meet the boxes
    ``±half`` (all (..., 3), box frame): the slab test. (..., 3) -> (...) bool."""
    safe = jnp.where(jnp.abs(direction) < 1e-12, 1e-12, direction)
    t1, t2 = (-half - origin) / safe, (half - origin) / safe
    near = jnp.max(jnp.minimum(t1, t2), axis=-1)
    far = jnp.min(jnp.maximum(t1, t2), axis=-1)
    return far >= jnp.maximum(near, 0.0)


def touch_sites(m: mujoco.MjModel) -> np.ndarray:
    """The sites (15,) of the scene's touch sensors, ``CONTACT_SENSORS`` order."""
    layout = scene.SENSOR_LAYOUT
    by_adr = {int(m.sensor_adr[i]): i for i in range(m.nsensor)}
    return np.array(
        [int(m.sensor_objid[by_adr[a]]) for a in range(layout.touch.start, layout.touch.stop)]
    )


def capsule_box_pairs(m: mujoco.MjModel, sensor_of_geom: np.ndarray) -> tuple[np.ndarray, ...]:
    """The contact pairs between a sensed capsule (a phalanx) and a box: capsule geoms
    (P,), box geoms (P,) and the capsule's contact sensor (P,)."""
    capsule, box = int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_BOX)
    pairs = []
    for g1, g2 in zip(m.pair_geom1, m.pair_geom2):
        for a, b in ((g1, g2), (g2, g1)):
            if m.geom_type[a] == capsule and m.geom_type[b] == box and sensor_of_geom[a] >= 0:
                pairs.append((a, b, sensor_of_geom[a]))
    return (
        tuple(np.array(column, np.int32).reshape(-1) for column in zip(*pairs))
        if pairs
        else (np.zeros(0, np.int32),) * 3
    )


def segment_box_distance(
    a: jax.Array,
    b: jax.Array,
    centre: jax.Array,
    rot: jax.Array,
    half: jax.Array,
    iterations: int = 32,
) -> jax.Array:
    """Distance from segments ``a``-``b`` (..., 3) to boxes (centre (..., 3), rotation
    (..., 3, 3) of the box frame in the world, half sizes (..., 3)); 0 where they meet.
    The distance to a convex box along a segment is convex in the segment's parameter, so
    a golden-section search finds its minimum (to 0.618^iterations of the length)."""

    def to_box(t):
        point = a + t[..., None] * (b - a)
        local = jnp.einsum("...ji,...j->...i", rot, point - centre)
        return jnp.linalg.norm(jnp.maximum(jnp.abs(local) - half, 0.0), axis=-1)

    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    low, high = jnp.zeros(a.shape[:-1]), jnp.ones(a.shape[:-1])
    left, right = high - ratio, low + ratio

    def narrow(_, search):
        # Golden section: the kept interior point is the next step's other one, so each
        # step measures one new point.
        low, high, left, right, at_left, at_right = search
        keep_left = at_left <= at_right
        low, high = jnp.where(keep_left, low, left), jnp.where(keep_left, right, high)
        fresh = jnp.where(keep_left, high - ratio * (high - low), low + ratio * (high - low))
        at_fresh = to_box(fresh)
        return (
            low,
            high,
            jnp.where(keep_left, fresh, right),
            jnp.where(keep_left, left, fresh),
            jnp.where(keep_left, at_fresh, at_right),
            jnp.where(keep_left, at_left, at_fresh),
        )

    search = (low, high, left, right, to_box(left), to_box(right))
    low, high, *_ = jax.lax.fori_loop(0, iterations, narrow, search)
    ends = jnp.minimum(to_box(jnp.zeros_like(low)), to_box(jnp.ones_like(low)))
    return jnp.minimum(to_box(0.5 * (low + high)), ends)


def _actuated_qpos_adr(m: mujoco.MjModel) -> np.ndarray:
    return np.array([m.jnt_qposadr[j] for j in m.actuator_trnid[:, 0]])


class MjxPhysics:
    """MJX, ``n_substeps`` ``mjx.step`` per control period (see module docstring)."""

    name = "mjx"

    def __init__(self, mj_model: mujoco.MjModel, n_substeps: int, contact_distance: float):
        self.mj_model = mj_model
        self.n_substeps = n_substeps
        self.contact_distance = contact_distance
        self.point_sites, self.sensor_of_geom = sensor_objects(mj_model)
        self.touch_sites = touch_sites(mj_model)
        self.touch_size = np.asarray(mj_model.site_size[self.touch_sites], np.float32)
        self.actuated_qadr = _actuated_qpos_adr(mj_model)
        self.capsule_box = capsule_box_pairs(mj_model, self.sensor_of_geom)
        self.mjx_model = put_model(mj_model)

    def pose(self, qpos: jax.Array, mocap_pos: jax.Array, mocap_quat: jax.Array) -> mjx.Data:
        data = mjx.make_data(self.mjx_model).replace(
            qpos=qpos, ctrl=qpos[self.actuated_qadr], mocap_pos=mocap_pos, mocap_quat=mocap_quat
        )
        with jax.default_matmul_precision("highest"):
            return mjx.forward(self.mjx_model, data)

    def step(
        self,
        data: mjx.Data,
        ctrl: jax.Array,
        model: mjx.Model | None = None,
        *,
        mocap_from: tuple | None = None,
    ) -> mjx.Data:
        """``model``: another compiled model of the same scene (benchmarks vary solver
        settings); default the physics' own. ``mocap_from``: see ``Physics.step``."""
        model = self.mjx_model if model is None else model
        data = data.replace(ctrl=ctrl)
        # GPUs default float32 matmuls to TF32 (10-bit mantissa), too coarse for the
        # constraint solver; the physics keeps full float32 (a no-op on CPU).
        with jax.default_matmul_precision("highest"):
            return substeps(model, data, self.n_substeps, mocap_from)

    def readings(self, data: mjx.Data) -> Readings:
        contact = data._impl.contact
        geom_sensor = jnp.asarray(self.sensor_of_geom)[contact.geom]  # (ncon, 2)
        sensor = jnp.max(geom_sensor, axis=-1)  # the agent geom's sensor; target geoms are -1
        touching = contact.dist < self.contact_distance
        one_hot = jax.nn.one_hot(sensor, len(sh.CONTACT_SENSORS))  # (ncon, 15); -1: zeros
        hits = one_hot * touching[:, None]
        # MJX runs no sensor stage. MuJoCo's touch sensor adds a contact's normal force
        # when the ray from the contact point along the normal meets the site's box; its
        # soft contacts push from within their margin (the scene's force_margin), so
        # here a contact within contact_distance whose ray meets the box reads as touch
        # (tests/test_profiles.py measures the agreement; penetration alone missed half).
        site = jnp.maximum(sensor, 0)
        centre = data.site_xpos[self.touch_sites][site]  # (ncon, 3)
        frame = data.site_xmat[self.touch_sites].reshape(-1, 3, 3)[site]  # (ncon, 3, 3)
        agent_first = geom_sensor[:, 0] >= 0
        normal = contact.frame[:, 0, :] * jnp.where(agent_first, 1.0, -1.0)[:, None]
        origin = jnp.einsum("cji,cj->ci", frame, contact.pos - centre)
        direction = jnp.einsum("cji,cj->ci", frame, normal)
        hit = ray_hits_box(origin, direction, jnp.asarray(self.touch_size)[site])
        pressing = hit & touching
        return Readings(
            qpos=data.qpos,
            qvel=data.qvel,
            points=data.site_xpos[self.point_sites],
            contacts=jnp.maximum(jnp.max(hits, axis=0, initial=0.0), self._capsule_box_near(data)),
            touch=jnp.max(one_hot * pressing[:, None], axis=0, initial=0.0),
            penetration=jnp.maximum(-jnp.min(contact.dist, initial=jnp.inf), 0.0),
            finite=jnp.isfinite(data.qpos).all() & jnp.isfinite(data.qvel).all(),
        )

    def _capsule_box_near(self, data: mjx.Data) -> jax.Array:
        """(15,) 0/1: a sensed phalanx capsule within ``contact_distance`` of a box. MJX's
        capsule-box collision lists a pair only once it penetrates, where native MuJoCo
        lists it from ``contact_distance`` apart (``benchmarks/contact_pairs.py``), so the
        proximity reading measures these pairs' distance itself."""
        capsules, boxes, sensors = self.capsule_box
        if capsules.size == 0:
            return jnp.zeros(len(sh.CONTACT_SENSORS))
        axis = data.geom_xmat[capsules].reshape(-1, 3, 3)[:, :, 2]  # (P, 3) capsule axes
        half_length = jnp.asarray(self.mj_model.geom_size[capsules, 1], jnp.float32)[:, None]
        centre = data.geom_xpos[capsules]
        gap = segment_box_distance(
            centre - half_length * axis,
            centre + half_length * axis,
            data.geom_xpos[boxes],
            data.geom_xmat[boxes].reshape(-1, 3, 3),
            jnp.asarray(self.mj_model.geom_size[boxes], jnp.float32),
        ) - jnp.asarray(self.mj_model.geom_size[capsules, 0], jnp.float32)
        near = (gap < self.contact_distance).astype(jnp.float32)  # (P,)
        return jnp.max(jax.nn.one_hot(sensors, len(sh.CONTACT_SENSORS)) * near[:, None], axis=0)

    def reserve(self, worlds: int) -> None:
        """MJX sizes each simulation alone: nothing to reserve."""


def put_model(mj_model: mujoco.MjModel) -> mjx.Model:
    """The MJX model of the scene, its sensor stage off (see module docstring)."""
    m = copy.copy(mj_model)
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_SENSOR
    return mjx.put_model(m)


def mjx_sizes(mj_model: mujoco.MjModel) -> dict[str, int]:
    """Sizes that drive MJX cost: contacts and constraint rows of one ``mjx.Data``."""
    data = mjx.make_data(put_model(mj_model))
    return {
        "max_contacts": int(data._impl.contact.dist.shape[0]),
        "constraint_rows": int(data._impl.efc_J.shape[0]),
    }


@struct.dataclass
class NativeState:
    """A native simulation between control periods (float32 in the JAX program)."""

    qpos: jax.Array  # (nq,)
    qvel: jax.Array  # (nv,)
    ctrl: jax.Array  # (nu,) set-points of the last control period
    mocap_pos: jax.Array  # (nmocap, 3)
    mocap_quat: jax.Array  # (nmocap, 4)
    time: jax.Array  # () seconds
    sensordata: jax.Array  # (nsensordata,) of the last substep's kinematics


def rest_state(
    m: mujoco.MjModel,
    actuated_qadr: np.ndarray,
    qpos: jax.Array,
    mocap_pos: jax.Array,
    mocap_quat: jax.Array,
) -> NativeState:
    """At rest at ``qpos`` (nq,), set-points on the actuated joints, the target's mocap
    bodies at ``mocap_pos`` / ``mocap_quat``; sensors not yet read (zeros)."""
    return NativeState(
        qpos=qpos,
        qvel=jnp.zeros(m.nv, jnp.float32),
        ctrl=qpos[actuated_qadr],
        mocap_pos=mocap_pos,
        mocap_quat=mocap_quat,
        time=jnp.zeros((), jnp.float32),
        sensordata=jnp.zeros(m.nsensordata, jnp.float32),
    )


def sensor_readings(state: NativeState, contact_distance: float) -> Readings:
    """The readings of a simulation whose engine computes the scene's sensors itself
    (native MuJoCo, MuJoCo Warp): from ``state.sensordata``."""
    layout = scene.SENSOR_LAYOUT
    found, dist = state.sensordata[layout.closest]
    per_geom = state.sensordata[layout.contacts].reshape(len(sh.CONTACT_SENSORS), 2)
    touching = (per_geom[:, 0] > 0) & (per_geom[:, 1] < contact_distance)
    return Readings(
        qpos=state.qpos,
        qvel=state.qvel,
        points=state.sensordata[layout.points].reshape(len(sh.HAND_POINTS), 3),
        contacts=touching.astype(jnp.float32),
        touch=(state.sensordata[layout.touch] > 0.0).astype(jnp.float32),
        penetration=jnp.where(found > 0, jnp.maximum(-dist, 0.0), 0.0),
        finite=jnp.isfinite(state.qpos).all() & jnp.isfinite(state.qvel).all(),
    )


def native_model(mj_model: mujoco.MjModel, contact_distance: float) -> mujoco.MjModel:
    """The model native MuJoCo steps: ``mj_model`` with its contact pairs listed from
    ``contact_distance`` apart and automatic reset off (a diverged simulation shows as
    NaN, which ends that episode, not as a silent reset to the initial pose). MuJoCo
    lists a pair's contacts closer than its margin plus its gap and lets those closer than
    the margin push (``SceneConfig.force_margin``), so the gap widens the listing and the
    forces stay as the scene has them. An exported policy's player loads this model."""
    m = copy.copy(mj_model)
    m.pair_gap[:] = np.maximum(contact_distance - m.pair_margin, 0.0)
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET
    return m


class NativePhysics:
    """C MuJoCo through ``mujoco.rollout`` on a thread pool (see module docstring)."""

    name = "native"

    def __init__(
        self,
        mj_model: mujoco.MjModel,
        n_substeps: int,
        contact_distance: float,
        threads: int | None = None,
    ):
        self.mj_model = mj_model
        self.n_substeps = n_substeps
        self.contact_distance = contact_distance
        self.actuated_qadr = _actuated_qpos_adr(mj_model)
        m = self.native_model = native_model(mj_model, contact_distance)
        self.threads = max(1, threads or os.cpu_count() or 1)
        self._datas = [mujoco.MjData(m) for _ in range(self.threads)]
        self._pool = mujoco.rollout.Rollout(nthread=self.threads if self.threads > 1 else 0)
        self._lock = threading.Lock()  # one rollout at a time (several devices may call)
        self._state_spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        if mujoco.mj_stateSize(m, self._state_spec) != 1 + m.nq + m.nv:
            raise ValueError(
                "NativePhysics expects a model without activations, history or plugins"
            )

    # ---------------------------------------------------------------- Physics
    def pose(self, qpos: jax.Array, mocap_pos: jax.Array, mocap_quat: jax.Array) -> NativeState:
        state = rest_state(self.mj_model, self.actuated_qadr, qpos, mocap_pos, mocap_quat)
        # One step computes the sensors at the given pose before it integrates; the
        # integrated state is dropped.
        _, _, _, sensordata = self._rollout(state, 1)
        return state.replace(sensordata=sensordata)

    def step(
        self, state: NativeState, ctrl: jax.Array, *, mocap_from: tuple | None = None
    ) -> NativeState:
        state = state.replace(ctrl=ctrl)
        path = None
        if mocap_from is not None:
            path = mocap_path(mocap_from, (state.mocap_pos, state.mocap_quat), self.n_substeps)
        qpos, qvel, time, sensordata = self._rollout(state, self.n_substeps, path)
        return state.replace(qpos=qpos, qvel=qvel, time=time, sensordata=sensordata)

    def readings(self, state: NativeState) -> Readings:
        return sensor_readings(state, self.contact_distance)

    def reserve(self, worlds: int) -> None:
        """``mujoco.rollout`` takes any batch: nothing to reserve."""

    # ------------------------------------------------------------- the callback
    def _rollout(self, state: NativeState, nstep: int, mocap: tuple | None = None):
        """(qpos, qvel, time, sensordata) after ``nstep`` physics steps, the mocap bodies
        at ``mocap``'s poses per step ((nstep, nmocap, 3), (nstep, nmocap, 4)) or, None,
        at ``state``'s throughout; under vmap one host call receives the whole batch."""
        path = mocap is not None
        mocap_pos, mocap_quat = mocap if path else (state.mocap_pos, state.mocap_quat)
        m = self.mj_model
        shapes = (
            jax.ShapeDtypeStruct((m.nq,), jnp.float32),
            jax.ShapeDtypeStruct((m.nv,), jnp.float32),
            jax.ShapeDtypeStruct((), jnp.float32),
            jax.ShapeDtypeStruct((m.nsensordata,), jnp.float32),
        )
        return jax.pure_callback(
            lambda *a: self.run(*a, nstep=nstep, path=path),
            shapes,
            state.time,
            state.qpos,
            state.qvel,
            state.ctrl,
            mocap_pos,
            mocap_quat,
            vmap_method="broadcast_all",
        )

    def run(self, time, qpos, qvel, ctrl, mocap_pos, mocap_quat, *, nstep: int, path: bool = False):
        """Host side: any leading batch shape; float32 in and out, float64 inside. With
        ``path`` the mocap poses hold one per step ((..., nstep, nmocap, 3 / 4))."""
        m = self.native_model
        lead = np.shape(qpos)[:-1]
        batch = int(np.prod(lead, dtype=np.int64))
        flat = lambda x, n: np.asarray(x, np.float64).reshape(batch, n)
        initial = np.concatenate([flat(time, 1), flat(qpos, m.nq), flat(qvel, m.nv)], axis=1)
        steps = nstep if path else 1  # one control row holds for every step
        per_step = lambda x, n: np.asarray(x, np.float64).reshape(batch, steps, n)
        control = np.concatenate(
            [
                np.broadcast_to(flat(ctrl, m.nu)[:, None, :], (batch, steps, m.nu)),
                per_step(mocap_pos, 3 * m.nmocap),
                per_step(mocap_quat, 4 * m.nmocap),
            ],
            axis=2,
        )
        with self._lock:
            states, sensordata = self._pool.rollout(
                m,
                self._datas,
                initial,
                control,
                control_spec=NATIVE_CONTROL_SPEC,
                nstep=nstep,
                initial_warmstart=np.zeros((batch, m.nv)),
            )
        last = states[:, -1]
        f32 = lambda x, shape: np.asarray(x, np.float32).reshape(lead + shape)
        return (
            f32(last[:, 1 : 1 + m.nq], (m.nq,)),
            f32(last[:, 1 + m.nq :], (m.nv,)),
            f32(last[:, 0], ()),
            f32(sensordata[:, -1], (m.nsensordata,)),
        )


class WarpPhysics:
    """MuJoCo Warp (MJX's ``impl="warp"``) inside the compiled program: the native
    model's contacts and sensors, stepped by Warp kernels on the GPU (or Warp's CPU
    device). Its state is a :class:`NativeState`; every control period starts from a
    fresh Warp data holding that state, with a cold solver start, as the native step
    does (``benchmarks/physics_agreement.py``: native to 3e-7 rad, median, in contact;
    ``tests/test_physics.py``: at most 2e-5 on resting contacts)."""

    name = "warp"

    def __init__(
        self,
        mj_model: mujoco.MjModel,
        n_substeps: int,
        contact_distance: float,
        worlds: int = WARP_WORLDS,
        constraints: int = WARP_CONSTRAINTS,
        contacts_per_world: int = WARP_CONTACTS_PER_WORLD,
    ):
        try:
            import warp  # MJX's Warp implementation needs it
        except ImportError as err:
            raise ImportError(
                "physics='warp' needs MuJoCo Warp: pip install -e '.[warp]' "
                "(mujoco-mjx[warp], warp-lang)"
            ) from err
        warp.config.quiet = True  # no banner on stdout when Warp starts
        self.mj_model = mj_model
        self.n_substeps = n_substeps
        self.contact_distance = contact_distance
        self.actuated_qadr = _actuated_qpos_adr(mj_model)
        m = native_model(mj_model, contact_distance)
        # Warp refuses the flag; it only changes what a blow-up does (NaN ends the episode).
        m.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
        self.native_model = m
        model = mjx.put_model(m, impl="warp")
        # Warp prints a warning whenever the solver stops at its iteration limit, as the
        # scene's 4 iterations routinely do in contact (native MuJoCo stays silent); the
        # warnings of overflowing buffers (contacts, constraint rows) stay on.
        from mujoco.mjx.third_party.mujoco_warp import OverflowType

        # Its contact sensors consider 64 contacts by default; the closest-contact sensor
        # matches every agent-target contact, more than 64 with the hands pressed together.
        impl = model.opt._impl.replace(
            warn_overflow=int(model.opt._impl.warn_overflow) & ~int(OverflowType.ITERATIONS),
            contact_sensor_maxmatch=WARP_SENSOR_MATCHES,
        )
        self.warp_model = model.replace(opt=model.opt.replace(_impl=impl))
        self.constraints = constraints
        self.contacts_per_world = contacts_per_world
        self.worlds = 0
        self.reserve(worlds)

    def reserve(self, worlds: int) -> None:
        """Room for ``worlds`` simulations stepped in one call (a learner's members x
        environments per device); before the program that steps them is traced. Warp
        allocates contacts for the whole batch at once (``naconmax`` spans all worlds),
        constraint rows per world (``njmax``)."""
        if worlds <= self.worlds:
            return
        self.worlds = worlds
        self.template = mjx.make_data(
            self.native_model,
            impl="warp",
            naconmax=self.contacts_per_world * worlds,
            njmax=self.constraints,
        )

    def _data(self, state: NativeState):
        return self.template.replace(
            qpos=state.qpos,
            qvel=state.qvel,
            ctrl=state.ctrl,
            mocap_pos=state.mocap_pos,
            mocap_quat=state.mocap_quat,
            time=state.time,
        )

    def pose(self, qpos: jax.Array, mocap_pos: jax.Array, mocap_quat: jax.Array) -> NativeState:
        state = rest_state(self.mj_model, self.actuated_qadr, qpos, mocap_pos, mocap_quat)
        data = mjx.forward(self.warp_model, self._data(state))
        return state.replace(sensordata=data.sensordata)

    def step(
        self, state: NativeState, ctrl: jax.Array, *, mocap_from: tuple | None = None
    ) -> NativeState:
        state = state.replace(ctrl=ctrl)
        data = substeps(self.warp_model, self._data(state), self.n_substeps, mocap_from)
        return state.replace(
            qpos=data.qpos, qvel=data.qvel, time=data.time, sensordata=data.sensordata
        )

    def readings(self, state: NativeState) -> Readings:
        return sensor_readings(state, self.contact_distance)


def make_physics(
    name: str, mj_model: mujoco.MjModel, n_substeps: int, contact_distance: float
) -> MjxPhysics | NativePhysics | WarpPhysics:
    """The physics ``name`` ('mjx', 'native', 'warp' or 'auto': native on CPUs, MJX
    elsewhere)."""
    if name == "auto":
        name = "native" if jax.default_backend() == "cpu" else "mjx"
    if name == "mjx":
        return MjxPhysics(mj_model, n_substeps, contact_distance)
    if name == "native":
        return NativePhysics(mj_model, n_substeps, contact_distance)
    if name == "warp":
        return WarpPhysics(mj_model, n_substeps, contact_distance)
    raise ValueError(f"unknown physics {name!r}; expected one of auto, {', '.join(PHYSICS)}")

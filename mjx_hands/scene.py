"""The hand-pair scene, composed with ``mujoco.MjSpec`` and made lean for MJX.

Agent: the 4-DoF arm of ``scenes/arm.xml`` carrying the gymnasium-robotics Shadow
hand (24 DoF, 20 actuators). Controls: ``ARM_JOINTS + HAND_JOINTS`` (24), position
servos whose set-points span each joint's range.

Target: a second Shadow hand built from **mocap bodies** -- one per rigid link,
posed per episode by the environment from forward kinematics of the requested
finger angles (:func:`target_poses`, from ``hand_kinematics``). It adds no degree of freedom and no
constraint row except its contacts with the agent.

What was changed from the stock hand model, and why (each item removes solver work):

* the 88 fixed tendons go: most only mirror joint limits; the four distal couplings
  ``J0 ~ J1`` become joint equalities (1 row each);
* ``frictionloss`` goes (1 row per joint in MJX, always allocated);
* every geom gets ``contype = conaffinity = 0``: the only contacts are explicit
  ``<pair>``s between agent collision geoms and target collision geoms, capped by
  the MJX numerics ``max_geom_pairs`` / ``max_contact_points``;
* the forearm's convex mesh collider goes (MJX mesh collisions are slow to
  compile and run); visual meshes stay for rendering and never collide;
* no gravity (a gravity-compensated arm; the target hand is kinematic).

What every physics implementation reads is defined here once, as MuJoCo sensors
(``SENSOR_LAYOUT`` gives their slices of ``sensordata``): the palm centre and the five
fingertip sites (``framepos``), the 15 contact sensors of ``CONTACT_SENSORS`` (one
``contact`` sensor per phalanx collision geom: how many contacts it has and the
distance of the closest), the closest agent-target contact (for the
penetration-free starts) and 15 ``touch`` sensors (summed normal force, newtons, of the
contacts inside a box site on the palmar side of each phalanx: the authors' sensors,
``TOUCH_SITES``).
A phalanx touches the target when its geom is closer than the environment's
``contact_distance``: native MuJoCo lists pairs closer than their margin plus gap, so
``physics.native_model`` widens its copy's gaps to list contacts from that distance; MJX
lists capsule-capsule pairs with their distance but capsule-box pairs only once they
penetrate, so ``physics.MjxPhysics`` measures the sensed capsule-box pairs' distance
itself. Agent-target contacts push from
``SceneConfig.force_margin`` apart (the pairs' margin; MuJoCo 3.17 and MJX let contacts
closer than the margin push, and the gap only widens what is listed).
"""

from __future__ import annotations

import dataclasses
import functools
import os

import mujoco
import numpy as np

from mjx_hands import hand_kinematics, package_data
from mjx_hands import shadow_hand as sh

SCENE_DIR = os.fspath(package_data.data_dir("scenes"))
AGENT = "agent/"
TARGET = "target/"

# Bodies of the hand whose collision geoms take part in agent-target contacts.
COLLISION_BODIES = tuple(sh.PHALANX_BODY.values()) + ("palm", "lfmetacarpal")
# Rigid links of the target hand that become mocap bodies (everything with a geom).
TARGET_LINKS = (
    "forearm", "wrist", "palm",
    "ffknuckle", "ffproximal", "ffmiddle", "ffdistal",
    "mfknuckle", "mfproximal", "mfmiddle", "mfdistal",
    "rfknuckle", "rfproximal", "rfmiddle", "rfdistal",
    "lfmetacarpal", "lfknuckle", "lfproximal", "lfmiddle", "lfdistal",
    "thproximal", "thmiddle", "thdistal",
)  # fmt: skip


@dataclasses.dataclass(frozen=True)
class SceneConfig:
    """Physics settings of the hand-pair scene (all trade accuracy for speed)."""

    timestep: float = 0.004
    """Physics step, seconds. The control period is a multiple of it."""
    solver_iterations: int = 4
    """Newton solver iterations per physics step."""
    ls_iterations: int = 8
    """Line-search iterations per solver iteration."""
    max_geom_pairs: int = 12
    """MJX: geom pairs kept per collision-function group (the closest ones)."""
    max_contact_points: int = 16
    """MJX: contacts kept per collision-function group."""
    condim: int = 3
    """Contact dimensionality of agent-target pairs (3: sliding friction)."""
    friction: float = 1.0
    """Sliding friction coefficient of agent-target contacts."""
    force_margin: float = 0.002
    """Distance (metres) from which agent-target contacts push (the pairs' margin): 2 mm,
    the physics every committed result trained with. MJX's JAX implementation ignores it
    for capsule-box pairs (it pushes there only on penetration) and then parts from
    native MuJoCo in contact by ~2e-2 rad per 40 ms period; at 0 (push from touching on)
    the three physics agree, MJX to ~7e-6 rad, and policies trained on MJX keep 0.98 of
    their success on native MuJoCo (``benchmarks/results/physics_agreement.md``): train
    on MJX at 0 for a policy meant for native MuJoCo or a robot."""


@dataclasses.dataclass(frozen=True)
class SensorLayout:
    """Slices of ``sensordata`` (length ``size``) holding what the environment reads."""

    points: slice  # (6 * 3,) palm centre + fingertips, world, ``HAND_POINTS`` order
    contacts: slice  # (15 * 2,) per phalanx geom (CONTACT_SENSORS order): number of
    #                  contacts, distance of the closest one
    closest: slice  # (2,) number of agent-target contacts, distance of the closest one
    touch: slice  # (15,) touch sensors (CONTACT_SENSORS order): normal force in the site, N
    size: int


_N_CONTACT = 2 * len(sh.CONTACT_SENSORS)
_N_POINTS = 3 * len(sh.HAND_POINTS)
_N_TOUCH = len(sh.CONTACT_SENSORS)
SENSOR_LAYOUT = SensorLayout(
    contacts=slice(0, _N_CONTACT),
    points=slice(_N_CONTACT, _N_CONTACT + _N_POINTS),
    closest=slice(_N_CONTACT + _N_POINTS, _N_CONTACT + _N_POINTS + 2),
    touch=slice(_N_CONTACT + _N_POINTS + 2, _N_CONTACT + _N_POINTS + 2 + _N_TOUCH),
    size=_N_CONTACT + _N_POINTS + 2 + _N_TOUCH,
)

_TOUCH_BOX = (0.009, 0.004, 0.013)
TOUCH_SITES: dict[str, tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]] = {
    **{f"{f}_middle": ((0, -0.005, 0.02), _TOUCH_BOX, (0, 0, 0)) for f in ("ff", "mf", "rf")},
    "lf_middle": ((0, -0.006, 0.015), _TOUCH_BOX, (0, 0, 0)),
    "th_middle": ((-0.007, 0, 0.015), _TOUCH_BOX, (0, 0.05, 1.57)),
    # The authors' proximal sensors are unused by every task; these are the project's
    # (the middle phalanx's box, centred on the longer proximal phalanx).
    **{f"{f}_proximal": ((0, -0.007, 0.0225), _TOUCH_BOX, (0, 0, 0)) for f in ("ff", "mf", "rf", "lf")},
    "th_proximal": ((-0.007, 0, 0.019), _TOUCH_BOX, (0, 0.05, 1.57)),
}  # fmt: skip
"""Touch sites added to the hand: sensor -> (pos, box half-sizes, euler) in the phalanx
body's frame. The middle ones are the authors' ``Tch_*tip_m`` sites (their
``robot.xml``); the distal ones are the stock model's ``Tch_*tip`` sites, the authors'
``Tch_*tip``."""

# mjtConDataBit bits of a contact sensor's data (found, dist) and its reductions.
_CONDATA_FOUND, _CONDATA_DIST = 1 << 0, 1 << 3
_REDUCE_MINDIST = 1


def _hand_spec() -> mujoco.MjSpec:
    """The stock gymnasium-robotics hand, loaded through its ``reach.xml`` wrapper."""
    return mujoco.MjSpec.from_file(os.path.join(sh.asset_dir(), "reach.xml"))


def _clean_hand(spec: mujoco.MjSpec) -> dict[str, tuple[float, float, float]]:
    """Strip the stock hand down for MJX (see module docstring); in place.

    Returns the stock actuators' ``(kp, force_lo, force_hi)`` by joint name, so that
    they can be re-created in the project's actuator order.
    """
    servo = {}
    for act in list(spec.actuators):
        servo[act.target.removeprefix(sh.PREFIX)] = (
            float(act.gainprm[0]), float(act.forcerange[0]), float(act.forcerange[1])
        )
        spec.delete(act)
    for element in list(spec.tendons) + list(spec.sensors) + list(spec.pairs):
        spec.delete(element)
    for name in ("target0", "target1", "target2", "target3", "target4"):
        spec.delete(spec.site(name))
    for name in ("finger0", "finger1", "finger2", "finger3", "finger4"):
        spec.delete(spec.site(name))
    spec.delete(spec.geom("floor0"))
    spec.delete(spec.geom(sh.hand_name("C_forearm")))
    for joint in spec.joints:
        joint.frictionloss = 0.0
    for geom in spec.geoms:
        geom.contype = 0
        geom.conaffinity = 0
        geom.margin = 0.0
    return servo


def _add_hand_actuators(spec: mujoco.MjSpec, servo: dict, prefix: str) -> None:
    """Position servos on the 20 hand joints in ``HAND_JOINTS`` order."""
    for name in sh.HAND_JOINTS:
        kp, flo, fhi = servo[name]
        joint = spec.joint(prefix + sh.hand_name(name))
        act = spec.add_actuator(name=f"{prefix}{name}", target=joint.name)
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_position(kp=kp, kv=0.05 * kp)
        act.ctrlrange = joint.range
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [flo, fhi]
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE


def _add_distal_couplings(spec: mujoco.MjSpec, prefix: str) -> None:
    for distal, middle in sh.COUPLED_DISTAL_JOINTS.items():
        data = np.zeros(mujoco.mjNEQDATA)
        data[1] = sh.DISTAL_COUPLING  # J0 = c * J1 (polynomial coefficients)
        spec.add_equality(
            type=mujoco.mjtEq.mjEQ_JOINT,
            name1=prefix + sh.hand_name(distal),
            name2=prefix + sh.hand_name(middle),
            data=data,
        )


def _add_agent(world: mujoco.MjSpec) -> None:
    arm = mujoco.MjSpec.from_file(os.path.join(SCENE_DIR, "arm.xml"))
    hand = _hand_spec()
    servo = _clean_hand(hand)
    for spec in (arm, hand):  # the stock hand declares user fields we do not use
        spec.nuser_jnt = spec.nuser_site = spec.nuser_tendon = -1
        spec.nuser_actuator = spec.nuser_sensor = -1
    hand.option.timestep, hand.option.iterations = world.option.timestep, world.option.iterations
    hand.njmax = hand.nconmax = -1
    hand.body(sh.hand_name("forearm")).pos = [0, 0, 0]  # mount frame = forearm frame
    world.worldbody.add_frame().attach_body(arm.body("shoulder_base"), AGENT, "")
    world.site(AGENT + "hand_mount").attach_body(hand.body(sh.hand_name("forearm")), AGENT, "")
    _add_hand_actuators(world, servo, AGENT)
    _add_distal_couplings(world, AGENT)
    palm = world.body(AGENT + sh.hand_name("palm"))
    palm.add_site(name=AGENT + "palm_center", pos=list(sh.PALM_CENTER), size=[0.005] * 3)


def _add_target(world: mujoco.MjSpec, hand_model: mujoco.MjModel) -> None:
    """Copy every link of the (stock-posed) hand as a mocap body with its geoms."""
    for link in TARGET_LINKS:
        bid = hand_model.body(sh.hand_name(link)).id
        body = world.worldbody.add_body(name=TARGET + link, mocap=True)
        for gid in np.flatnonzero(hand_model.geom_bodyid == bid):
            g = hand_model.geom(gid)
            if g.name == sh.hand_name("C_forearm"):
                continue
            geom = body.add_geom(
                name=TARGET + g.name.removeprefix(sh.PREFIX),
                type=mujoco.mjtGeom(int(g.type[0])),
                size=g.size,
                pos=g.pos,
                quat=g.quat,
                rgba=[0.85, 0.72, 0.62, 1.0] if g.group[0] == 1 else [0.85, 0.72, 0.62, 0.0],
                group=int(g.group[0]),
                contype=0,
                conaffinity=0,
            )
            if g.type[0] == mujoco.mjtGeom.mjGEOM_MESH:
                geom.meshname = AGENT + hand_model.mesh(int(g.dataid[0])).name
        if link == "palm":
            body.add_site(name=TARGET + "palm_center", pos=list(sh.PALM_CENTER), size=[0.005] * 3)


def _add_pairs(world: mujoco.MjSpec, cfg: SceneConfig) -> None:
    """Explicit agent-target contact pairs between collision geoms."""
    agent = [g for g in world.geoms if g.name.startswith(AGENT + sh.hand_name("C_"))]
    agent = [g for g in agent if g.parent.name.removeprefix(AGENT + sh.PREFIX) in COLLISION_BODIES]
    target = [g for g in world.geoms if g.name.startswith(TARGET + "C_")]
    target = [g for g in target if g.parent.name.removeprefix(TARGET) in COLLISION_BODIES]
    for a in agent:
        for t in target:
            world.add_pair(
                geomname1=a.name,
                geomname2=t.name,
                condim=cfg.condim,
                friction=[cfg.friction, cfg.friction, 0.005, 0.0001, 0.0001],
                margin=cfg.force_margin,
            )


def _add_sensors(world: mujoco.MjSpec) -> None:
    """The sensors of ``SENSOR_LAYOUT``, in its order (see module docstring)."""
    for finger, phalanx in (name.split("_") for name in sh.CONTACT_SENSORS):
        geom = AGENT + sh.hand_name("C_" + sh.PHALANX_BODY[(finger, phalanx)])
        world.add_sensor(
            name=f"contact/{finger}_{phalanx}",
            type=mujoco.mjtSensor.mjSENS_CONTACT,
            objtype=mujoco.mjtObj.mjOBJ_GEOM,
            objname=geom,
            intprm=[_CONDATA_FOUND | _CONDATA_DIST, _REDUCE_MINDIST, 1],
        )
    for point, site in zip(sh.HAND_POINTS, ("palm_center",) + tuple(
        sh.hand_name(f"S_{tip}") for tip in sh.FINGERTIPS
    )):
        world.add_sensor(
            name=f"point/{point}",
            type=mujoco.mjtSensor.mjSENS_FRAMEPOS,
            objtype=mujoco.mjtObj.mjOBJ_SITE,
            objname=AGENT + site,
        )
    world.add_sensor(  # every contact matches: all of them are agent-target pairs
        name="closest_contact",
        type=mujoco.mjtSensor.mjSENS_CONTACT,
        intprm=[_CONDATA_FOUND | _CONDATA_DIST, _REDUCE_MINDIST, 1],
    )
    for sensor in sh.CONTACT_SENSORS:
        finger, phalanx = sensor.split("_")
        site = f"Tch_{finger}tip" if phalanx == "distal" else f"Tch_{sensor}"
        world.add_sensor(
            name=f"touch/{sensor}",
            type=mujoco.mjtSensor.mjSENS_TOUCH,
            objtype=mujoco.mjtObj.mjOBJ_SITE,
            objname=AGENT + sh.hand_name(site),
        )


def _add_touch_sites(world: mujoco.MjSpec) -> None:
    """The middle and proximal phalanges' touch sites of ``TOUCH_SITES`` on the agent."""
    for sensor, (pos, size, euler) in TOUCH_SITES.items():
        finger, phalanx = sensor.split("_")
        body = world.body(AGENT + sh.hand_name(sh.PHALANX_BODY[(finger, phalanx)]))
        site = body.add_site(
            name=AGENT + sh.hand_name(f"Tch_{sensor}"),
            type=mujoco.mjtGeom.mjGEOM_BOX,
            pos=list(pos),
            size=list(size),
            group=4,
        )
        site.alt.euler = list(euler)


def build_spec(cfg: SceneConfig = SceneConfig()) -> mujoco.MjSpec:
    """The full hand-pair scene as an ``MjSpec`` (see module docstring)."""
    world = mujoco.MjSpec.from_file(os.path.join(SCENE_DIR, "world.xml"))
    world.option.timestep = cfg.timestep
    world.option.iterations = cfg.solver_iterations
    world.option.ls_iterations = cfg.ls_iterations
    world.meshdir = os.path.join(sh.asset_dir(), "..", "stls", "hand")
    _add_agent(world)
    _add_target(world, hand_kinematics.hand_model())
    _add_pairs(world, cfg)
    _add_touch_sites(world)
    _add_sensors(world)
    world.add_numeric(name="max_geom_pairs", data=[cfg.max_geom_pairs])
    world.add_numeric(name="max_contact_points", data=[cfg.max_contact_points])
    return world


@functools.cache
def build_model(cfg: SceneConfig = SceneConfig()) -> mujoco.MjModel:
    """Compiled hand-pair model (cached per config)."""
    return build_spec(cfg).compile()


@dataclasses.dataclass(frozen=True)
class TargetPoses:
    """Target-hand poses for a batch of finger configurations, in the palm frame.

    The palm frame has its origin at the palm centre and the palm body's axes.

    Attributes:
      link_pos: (N, len(TARGET_LINKS), 3) positions of the mocap links.
      link_quat: (N, len(TARGET_LINKS), 4) orientations of the mocap links.
      point_pos: (N, 6, 3) palm centre (zero) and fingertips, ``HAND_POINTS`` order.
      point_rot: (N, 6, 3, 3) palm body and distal-body orientations.
    """

    link_pos: np.ndarray
    link_quat: np.ndarray
    point_pos: np.ndarray
    point_rot: np.ndarray


def target_poses(angles: np.ndarray) -> TargetPoses:
    """Forward kinematics of the lone hand for finger angles (N, 20) in HAND_JOINTS order.

    Angles are clipped into the model's joint ranges (coupled distal joints too).
    """
    pose = hand_kinematics.forward_kinematics(np.atleast_2d(angles))
    link_pos, link_quat = hand_kinematics.link_poses(angles, TARGET_LINKS)
    return TargetPoses(
        link_pos=link_pos, link_quat=link_quat, point_pos=pose.points, point_rot=pose.frames
    )

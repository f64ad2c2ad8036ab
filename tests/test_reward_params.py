"""Algorithm 1 against a brute-force loop reference on synthetic demonstrations."""

from __future__ import annotations

import dataclasses
import math

import jax
import numpy as np
import pytest

from mjx_hands import reward_params as rp
from mjx_hands.mocap import Demonstration
from mjx_hands.reward_params import RewardWeights

Demo = Demonstration  # Algorithm 1 reads the fields; tests build them directly


def rotation(axis, angle):
    """Rodrigues: rotation matrix about ``axis`` by ``angle``."""
    x, y, z = np.asarray(axis, float) / np.linalg.norm(axis)
    c, s = math.cos(angle), math.sin(angle)
    k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + s * k + (1 - c) * (k @ k)


T_TOUCH, I_TOUCH, J_TOUCH, D_TOUCH = 17, 2, 3, 0.004


def make_demo(task="handshake", fps=100.0, T=40, contact=(15, 30), seed=0, name="synthetic/0"):
    """Actor point 2 (fftip) passes target point 3 (mftip) at 4 mm at frame 17.

    The target hand lies in the z = 0 plane of its palm frame; every other actor point
    stays at z >= 3 cm, and actor point 2 approaches from above, so the closest pair is
    unique. After contact_end (frame 35) actor point 4 comes within 1 mm of target
    point 1, which Algorithm 1 must ignore.
    """
    rng = np.random.default_rng(seed)
    tips = np.array([[0.05, 0.04], [0.09, 0.02], [0.095, 0.0], [0.09, -0.02], [0.08, -0.04]])
    target_points = np.zeros((T, 6, 3))
    target_frames = np.zeros((T, 6, 3, 3))
    target_frames[:, 0] = np.eye(3)
    axes = rng.normal(size=(5, 3))
    for t in range(T):
        for j in range(1, 6):
            wobble = 0.002 * np.array([math.sin(0.3 * t + j), math.cos(0.2 * t + j)])
            target_points[t, j, :2] = tips[j - 1] + wobble
            target_frames[t, j] = rotation(axes[j - 1], 0.3 * j + 0.02 * t)
    actor_points = np.zeros((T, 6, 3))
    u = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    for t in range(T):
        for i in range(6):
            actor_points[t, i] = [0.02 * i, 0.01 * i - 0.02, 0.03 + 0.01 * i + 0.001 * t]
        actor_points[t, I_TOUCH] = target_points[t, J_TOUCH] + u * (
            D_TOUCH + 0.005 * abs(t - T_TOUCH)
        )
    if T > 35:
        actor_points[35, 4] = target_points[35, 1] + [0, 0, 0.001]
    t = np.arange(T)[:, None]
    actor_joints = rng.uniform(-0.5, 0.5, 20) + 0.01 * t * rng.uniform(-1, 1, 20)
    target_joints = rng.uniform(-0.5, 0.5, 20) + 0.01 * t * rng.uniform(-1, 1, 20)
    tilt = rotation([1, 0, 0], 2.0)
    palm_rot = np.stack([rotation([0.2, 0.1, 1.0], 0.05 * k) @ tilt for k in range(T)])
    return Demo(
        task=task, name=name, source="synthetic", fps=fps,
        actor_joints=actor_joints, target_joints=target_joints,
        actor_points=actor_points, actor_palm_rot=palm_rot,
        target_points=target_points, target_frames=target_frames,
        contact_begin=contact[0], contact_end=contact[1],
    )  # fmt: skip


# ---------------------------------------------------------------- brute-force reference


def reference_alg1(demo, weights, dt):
    """Algorithm 1 written as plain loops over frames, points and control steps."""
    best = (math.inf, None, None, None)
    for t in range(demo.contact_begin, demo.contact_end + 1):
        for i in range(1, 6):
            for j in range(6):
                diff = demo.actor_points[t, i] - demo.target_points[t, j]
                d = math.sqrt(sum(c * c for c in diff))
                if d < best[0]:
                    best = (d, t, i, j)
    d_min, t_min, _, j_min = best

    def offset(t, i):
        R = demo.target_frames[t, j_min]
        diff = demo.actor_points[t, i] - demo.target_points[t, j_min]
        return np.array([sum(R[b, a] * diff[b] for b in range(3)) for a in range(3)])

    def dist(t, i):
        return float(np.sqrt(np.sum((demo.actor_points[t, i] - demo.target_points[t, j_min]) ** 2)))

    r = demo.fps * dt
    n_valid = 0
    while n_valid * r <= t_min + 1e-9:
        n_valid += 1

    def lerp(x, k):
        f = min(k * r, t_min)
        lo = math.floor(f)
        hi = min(lo + 1, len(x) - 1)
        return (1 - (f - lo)) * x[lo] + (f - lo) * x[hi]

    offsets = np.array([[offset(t, i) for i in range(6)] for t in range(len(demo.actor_points))])
    floor = rp.DISTANCE_FLOOR
    if weights.position_points == "fingertips":
        w = [0.0]
        for i in range(1, 6):
            w.append(weights.K_p * max(d_min, floor) / max(dist(t_min, i), floor))
    else:
        w = [weights.K_p] + [0.0] * 5
    return {
        "t_min": t_min, "j_min": j_min, "d_min": d_min, "n_valid": n_valid,
        "goal_offsets": np.array([offset(t_min, i) for i in range(6)]),
        "goal_angles": demo.actor_joints[t_min],
        "ref_offsets": lambda k: lerp(offsets, k),
        "ref_angles": lambda k: lerp(demo.actor_joints, k),
        "ref_palm_pos": lambda k: lerp(demo.actor_points[:, 0], k),
        "ref_target_joints": lambda k: lerp(demo.target_joints, k),
        "w_position": np.array(w),
    }  # fmt: skip


# ------------------------------------------------------------- reusable plausibility check


def check_alg1_plausible(params, demo, weights=RewardWeights(), max_offset=0.25):
    """Sanity of one demo's (unstacked) params; reusable on real demonstrations."""
    p = jax.tree.map(np.asarray, params)
    for name, leaf in dataclasses.asdict(p).items():
        assert np.all(np.isfinite(leaf)), name
    t_min = int(p.t_min_frame)
    assert demo.contact_begin <= t_min <= demo.contact_end, (t_min, demo.contact_begin)
    assert 0 <= int(p.j_min) < 6
    assert 0 <= int(p.t_min_step) < int(p.imitation_length) <= p.ref_angles.shape[0]
    assert int(p.t_min_step) + 1 == int(p.imitation_length)
    assert int(p.contact_begin_step) <= int(p.contact_end_step)
    d_tips = np.linalg.norm(p.goal_offsets[1:], axis=-1)
    assert np.all(d_tips <= max_offset), d_tips
    assert float(p.d_min) == pytest.approx(d_tips.min(), abs=1e-5)
    np.testing.assert_allclose(p.goal_angles, demo.actor_joints[t_min], atol=1e-6)
    d_floor = max(float(p.d_min), rp.DISTANCE_FLOOR)
    if weights.position_points == "fingertips":
        assert p.w_position[0] == 0
        tips = p.w_position[1:]
        assert np.all(tips >= weights.K_p * d_floor / max_offset - 1e-6), tips
        assert np.all(tips <= weights.K_p + 1e-6) and tips.max() == pytest.approx(weights.K_p)
    else:
        np.testing.assert_allclose(p.w_position, [weights.K_p, 0, 0, 0, 0, 0], atol=1e-6)
    eye = np.broadcast_to(np.eye(3), p.ref_palm_rot.shape)
    np.testing.assert_allclose(p.ref_palm_rot @ np.swapaxes(p.ref_palm_rot, -1, -2), eye, atol=1e-5)
    assert np.all(np.linalg.det(p.ref_palm_rot) > 0)


# ------------------------------------------------------------------------------ tests


@pytest.mark.parametrize("fps, n_valid", [(100.0, 5), (120.0, 4), (60.0, 8)])
def test_known_closest_approach(fps, n_valid):
    demo = make_demo(fps=fps)
    params = rp.algorithm1(demo, RewardWeights(), 0.04)
    assert int(params.t_min_frame) == T_TOUCH
    assert int(params.j_min) == J_TOUCH
    assert float(params.d_min) == pytest.approx(D_TOUCH, abs=1e-7)
    assert int(params.imitation_length) == n_valid
    assert int(params.t_min_step) == n_valid - 1
    assert params.ref_angles.shape == (n_valid, 20)
    # The touching fingertip gets K_p, its offset is 4 mm in target body 3's frame.
    assert params.w_position[I_TOUCH] == pytest.approx(1.0)
    assert np.linalg.norm(params.goal_offsets[I_TOUCH]) == pytest.approx(D_TOUCH, abs=1e-7)
    check_alg1_plausible(params, demo)


@pytest.mark.parametrize("fps", [100.0, 120.0, 60.0, 37.0])
@pytest.mark.parametrize("name", ["full", "baseline1", "baseline2", "no_imitation"])
def test_matches_loop_reference(fps, name):
    weights = rp.variant(name, RewardWeights(K_p=2.0, K_alpha=0.3, K_c=0.7, K_a=0.05))
    demo = make_demo(fps=fps, seed=3)
    ref = reference_alg1(demo, weights, 0.04)
    length = ref["n_valid"] + 3
    p = rp.algorithm1(demo, weights, 0.04, length=length)
    assert int(p.t_min_frame) == ref["t_min"] and int(p.j_min) == ref["j_min"]
    assert float(p.d_min) == pytest.approx(ref["d_min"], rel=1e-6)
    assert int(p.imitation_length) == ref["n_valid"]
    np.testing.assert_allclose(p.goal_offsets, ref["goal_offsets"], atol=1e-6)
    np.testing.assert_allclose(p.goal_angles, ref["goal_angles"], atol=1e-6)
    np.testing.assert_allclose(p.w_position, ref["w_position"], rtol=1e-6)
    for k in range(length):  # rows past the valid length repeat the t_min value
        np.testing.assert_allclose(p.ref_offsets[k], ref["ref_offsets"](k), atol=1e-6)
        np.testing.assert_allclose(p.ref_angles[k], ref["ref_angles"](k), atol=1e-6)
        np.testing.assert_allclose(p.ref_palm_pos[k], ref["ref_palm_pos"](k), atol=1e-6)
        np.testing.assert_allclose(p.ref_target_joints[k], ref["ref_target_joints"](k), atol=1e-6)
    np.testing.assert_allclose(p.ref_offsets[-1], ref["goal_offsets"], atol=1e-6)
    np.testing.assert_allclose(p.ref_angles[-1], ref["goal_angles"], atol=1e-6)
    np.testing.assert_allclose(p.w_angle, np.full(20, weights.K_alpha), rtol=1e-6)
    np.testing.assert_allclose(p.w_action, np.full(24, weights.K_a), rtol=1e-6)
    required = np.zeros(15, bool)
    for s in rp.REQUIRED_CONTACTS["handshake"]:
        required[rp.shadow_hand.CONTACT_SENSORS.index(s)] = True
    np.testing.assert_array_equal(p.required_contacts, required)
    np.testing.assert_allclose(p.w_contact, required * weights.K_c * weights.contact, rtol=1e-6)
    assert float(p.contact_bias) == 0.0  # the bonus form
    k_on = 1.0 if weights.imitation else 0.0
    np.testing.assert_allclose(
        p.w_imitation_position, weights.K_pI * k_on * ref["w_position"], rtol=1e-6
    )
    np.testing.assert_allclose(
        p.w_imitation_angle, np.full(20, weights.K_alphaI * k_on * weights.K_alpha), rtol=1e-6
    )
    check_alg1_plausible(p, demo, weights)


def test_palm_rotation_reference_is_interpolated_rotation():
    demo = make_demo(fps=120.0)
    p = rp.algorithm1(demo)
    r = 120.0 * 0.04
    np.testing.assert_allclose(p.ref_palm_rot[0], demo.actor_palm_rot[0], atol=1e-6)
    for k in range(int(p.imitation_length)):
        f = k * r
        lo = int(f)
        # The palm turns 0.05 rad per frame: a proper interpolation stays within that
        # angle of both bracketing frames.
        for frame in (lo, min(lo + 1, len(demo.actor_palm_rot) - 1)):
            rel = p.ref_palm_rot[k].T @ demo.actor_palm_rot[frame]
            angle = math.acos(np.clip((np.trace(rel) - 1) / 2, -1, 1))
            assert angle <= 0.05 + 1e-5


def test_goal_offsets_reproduce_demo_points():
    """Placing the goal offsets on the demo's own target hand gives the actor's points,
    in any world frame (the env evaluates them with world positions/rotations)."""
    from mjx_hands.rewards import goal_positions

    demo = make_demo()
    p = rp.algorithm1(demo)
    t = int(p.t_min_frame)
    R, c = rotation([0.4, -1.0, 0.3], 1.1), np.array([0.3, -0.2, 1.0])
    world_pts = demo.target_points[t] @ R.T + c
    world_rot = np.einsum("ab,jbc->jac", R, demo.target_frames[t])
    goal = goal_positions(world_pts, world_rot, p.j_min, p.goal_offsets)
    np.testing.assert_allclose(goal, demo.actor_points[t] @ R.T + c, atol=1e-5)


def test_build_task_params_stacks_and_picks_inside_jit():
    demos = [make_demo(fps=f, seed=s, name=f"d{s}") for s, f in enumerate([100.0, 120.0, 60.0])]
    params = rp.build_task_params(demos)
    L = 8  # the longest imitation length (60 Hz)
    expected = {
        "j_min": (3,), "ref_offsets": (3, L, 6, 3), "ref_angles": (3, L, 20),
        "ref_palm_pos": (3, L, 3), "ref_palm_rot": (3, L, 3, 3), "ref_target_joints": (3, L, 20),
        "goal_offsets": (3, 6, 3), "goal_angles": (3, 20), "w_position": (3, 6),
        "w_angle": (3, 20), "w_contact": (3, 15), "w_action": (3, 24),
        "required_contacts": (3, 15), "imitation_length": (3,),
    }  # fmt: skip
    for field, shape in expected.items():
        assert getattr(params, field).shape == shape, field
    for leaf in jax.tree.leaves(params):
        assert isinstance(leaf, jax.Array) and leaf.shape[0] == 3
    np.testing.assert_array_equal(params.imitation_length, [5, 4, 8])

    pick = jax.jit(lambda params, i: jax.tree.map(lambda x: x[i], params))
    for i, demo in enumerate(demos):
        one = pick(params, i)
        alone = rp.algorithm1(demo, length=L)
        for a, b in zip(jax.tree.leaves(one), jax.tree.leaves(alone)):
            np.testing.assert_allclose(np.asarray(a), b, atol=1e-6)
        check_alg1_plausible(one, demo)


def test_stack_params_requires_common_length():
    a = rp.algorithm1(make_demo(fps=100.0))
    b = rp.algorithm1(make_demo(fps=60.0))
    with pytest.raises(ValueError, match="reference lengths differ"):
        rp.stack_params([a, b])
    stacked = rp.stack_params([a, a])
    assert stacked.ref_angles.shape == (2, 5, 20)


def test_variants():
    assert rp.variant("full") == RewardWeights()
    assert rp.variant("baseline1").position_points == "palm"
    assert rp.variant("baseline2").contact is False
    assert rp.variant("no_imitation").imitation is False
    base = RewardWeights(K_p=3.0)
    assert rp.variant("baseline2", base).K_p == 3.0
    # One vocabulary: the baselines are the authors' configs, without imitation unless
    # named so; a reward form alone keeps the imitation switch as it is.
    assert not rp.variant("baseline1").imitation and rp.variant("baseline1_imitation").imitation
    assert rp.reward_form("baseline1") == rp.variant("baseline1_imitation")
    with pytest.raises(ValueError, match="expected one of full, no_imitation, baseline1"):
        rp.variant("baseline3")
    with pytest.raises(ValueError, match="unknown reward form 'no_imitation'"):
        rp.reward_form("no_imitation")


def test_required_contacts_are_sensors():
    names = rp.shadow_hand.CONTACT_SENSORS
    handshake = rp.required_contact_mask("handshake")
    # The authors' touch sensors: middle phalanges of all five fingers (handshake); distal
    # and middle of index to little finger (clap); the index fingertip (E.T.).
    assert [names[i] for i in np.flatnonzero(handshake)] == [
        f"{f}_middle" for f in ("th", "ff", "mf", "rf", "lf")
    ]
    clap = rp.required_contact_mask("handclap")
    assert sorted(names[i] for i in np.flatnonzero(clap)) == sorted(
        f"{f}_{p}" for f in ("ff", "mf", "rf", "lf") for p in ("distal", "middle")
    )
    assert np.flatnonzero(rp.required_contact_mask("et")).tolist() == [3]  # ff_distal
    assert rp.success_group_mask("handclap").any(-1).sum() == 4  # one group per finger
    for task in ("handshake", "handclap", "et"):  # the groups cover the rewarded sensors
        np.testing.assert_array_equal(
            rp.success_group_mask(task).any(0), rp.required_contact_mask(task)
        )
    with pytest.raises(ValueError, match="unknown task"):
        rp.required_contact_mask("hug")
    with pytest.raises(ValueError, match="unknown task"):
        rp.success_group_mask("hug")


def test_touching_fingertip_weight_is_floored():
    demo = make_demo()
    pts = demo.actor_points.copy()
    pts[T_TOUCH, I_TOUCH] = demo.target_points[T_TOUCH, J_TOUCH]  # exact touch: d = 0
    p = rp.algorithm1(dataclasses.replace(demo, actor_points=pts))
    assert float(p.d_min) == 0.0
    assert np.all(np.isfinite(p.w_position)) and p.w_position[I_TOUCH] == pytest.approx(1.0)
    assert np.all(p.w_position[1:] > 0)


@pytest.mark.parametrize(
    "change, match",
    [
        ({"contact_end": 40}, "beyond the data"),
        ({"contact_begin": 31}, "contact_begin <= contact_end"),
        ({"contact_begin": -1}, "contact_begin <= contact_end"),
        ({"task": "hug"}, "unknown task"),
        ({"fps": 0.0}, "fps must be"),
        ({"actor_joints": np.zeros((40, 19))}, "actor_joints has shape"),
        ({"target_frames": np.zeros((39, 6, 3, 3))}, "target_frames has shape"),
    ],
)
def test_bad_demo_raises(change, match):
    with pytest.raises(ValueError, match=match):
        rp.algorithm1(dataclasses.replace(make_demo(), **change))


def test_non_finite_inside_window_raises_outside_ignored():
    demo = make_demo()
    pts = demo.actor_points.copy()
    pts[38] = np.nan  # after contact_end: irrelevant
    rp.algorithm1(dataclasses.replace(demo, actor_points=pts))
    pts[20] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        rp.algorithm1(dataclasses.replace(demo, actor_points=pts))


def test_bad_lists_and_config_raise():
    with pytest.raises(ValueError, match="at least one"):
        rp.build_task_params([])
    with pytest.raises(ValueError, match="at least one"):
        rp.stack_params([])
    with pytest.raises(ValueError, match="one task"):
        rp.build_task_params([make_demo(), make_demo(task="et")])
    with pytest.raises(ValueError, match="dt must be"):
        rp.algorithm1(make_demo(), dt=0.0)
    with pytest.raises(ValueError, match="shorter than the imitation length"):
        rp.algorithm1(make_demo(), length=2)
    with pytest.raises(ValueError, match="position_points"):
        RewardWeights(position_points="wrist")
    with pytest.raises(ValueError, match="K_c"):
        RewardWeights(K_c=-1.0)


def test_search_window_ends_at_contact_end():
    # The 1 mm pass at frame 35 counts only once the window includes it.
    p = rp.algorithm1(make_demo(contact=(15, 39)))
    assert (int(p.t_min_frame), int(p.j_min)) == (35, 1)
    assert float(p.d_min) == pytest.approx(0.001, abs=1e-7)
    assert p.w_position[4] == pytest.approx(1.0)


def test_closest_approach_ignores_passes_before_the_contact_window():
    demo = make_demo(contact=(15, 30))
    points = demo.actor_points.copy()
    points[5, 2] = demo.target_points[5, 3]  # an exact touch before the window opens
    early = dataclasses.replace(demo, actor_points=points)
    t_min, _, _, d_min = rp.closest_approach(early)
    assert 15 <= t_min <= 30
    assert d_min > 0


@pytest.mark.parametrize("task", ["handshake", "handclap", "et"])
@pytest.mark.parametrize("source", ["optitrack", "synthetic"])
def test_algorithm1_is_plausible_on_recorded_and_generated_demos(task, source):
    from conftest import real_data_or_skip

    from mjx_hands import mocap

    path = real_data_or_skip() if source == "optitrack" else None
    demos = mocap.load_demonstrations(task, source=source, path=path)
    stacked = rp.build_task_params(demos, rp.RewardWeights(), rp.CONTROL_DT)
    for i, demo in enumerate(demos):
        check_alg1_plausible(jax.tree.map(lambda x, i=i: np.asarray(x[i]), stacked), demo)

"""The paper profile against the authors' environment, written out independently here:
their configs' weights, their reward's sign and form, their critic clip, target boxes,
observation and touch sensors (numbers from ``christsa/gym``,
``gym/envs/human_robot_interaction/config/*.yaml``, ``interactions/*.py``, ``hri_env.py``,
and ``christsa/baselines``, ``baselines/her/``)."""

from __future__ import annotations

import dataclasses

import jax
import mujoco
import numpy as np
import pytest

from mjx_hands import physics, profiles, reward_params, rewards, scene, train_config
from mjx_hands import shadow_hand as sh
from mjx_hands.env_config import EnvConfig

# (W_pos, W_f, W_ang, W_ipos, W_iang) of config/<task>.yaml, <task>_baseline1/2.yaml.
AUTHORS = {
    ("handshake", "full"): (4, 0.5, 0.0, 0, 0),
    ("handshake", "baseline1"): (4, 0.17, 0.0, 0, 0),
    ("handshake", "baseline2"): (1, 0.0, 0.2, 1, 0.2),
    ("handclap", "full"): (1, 0.1, 0.5, 0, 0),
    ("handclap", "baseline1"): (1, 0.1, 0.25, 0, 0),
    ("handclap", "baseline2"): (1, 0.0, 0.2, 0, 0),
    ("et", "full"): (6, 0.5, 0.2, 0, 0),
    ("et", "baseline1"): (4, 0.2, 0.5, 0, 0),
    ("et", "baseline2"): (1, 0.0, 0.2, 0, 0),
}
# FORCE_GOALS per TOUCH_SENSORS entry, in the project's sensor names.
FORCE_GOALS = {
    "handshake": {f"{f}_middle": 1 for f in ("th", "ff", "mf", "rf", "lf")},
    "handclap": {f"{f}_{p}": int(f != "th") for f in sh.FINGERS for p in ("distal", "middle")},
    "et": {"ff_distal": 1},
}
EPISODE = {"handshake": 100, "handclap": 75, "et": 75}


@pytest.mark.parametrize("task,reward", sorted(AUTHORS))
def test_paper_weights_are_the_authors_configs(task, reward):
    w_pos, w_f, w_ang, w_ipos, w_iang = AUTHORS[(task, reward)]
    weights = profiles.reward_weights("paper", task, reward, imitation=False)
    assert (weights.K_p, weights.K_c, weights.K_alpha) == (w_pos, w_f, w_ang)
    assert (weights.K_pI, weights.K_alphaI) == (w_ipos, w_iang)  # released as they are
    assert weights.K_a == 0.0  # their reward has no action term
    assert weights.position_points == ("palm" if reward == "baseline1" else "fingertips")
    assert weights.contact_form == "penalty" and weights.imitation_weights == "absolute"
    forbidden = {s for s, goal in FORCE_GOALS[task].items() if goal == 0}
    assert set(weights.forbidden_contacts) == forbidden
    with_imitation = profiles.reward_weights("paper", task, reward, imitation=True)
    expected = (w_ipos, w_iang) if w_ipos or w_iang else (1.0, 0.2)  # their handshake b2's
    assert (with_imitation.K_pI, with_imitation.K_alphaI) == expected and with_imitation.imitation


def test_set_knobs_override_every_paper_variant_and_unknown_profiles_are_named():
    knobs = reward_params.RewardKnobs(K_c=0.3)
    for reward in ("full", "baseline1"):
        assert profiles.reward_weights("paper", "et", reward, False, knobs).K_c == 0.3
    with pytest.raises(ValueError, match="unknown profile 'papr'.*project, paper"):
        profiles.reward_weights("papr", "et", "full", False)


def _demo(task: str):
    from test_reward_params import make_demo

    return dataclasses.replace(make_demo(), task=task)


@pytest.mark.parametrize("task", ["handshake", "handclap", "et"])
def test_paper_contact_term_is_the_authors_l1_error_to_their_force_goals(task):
    """r_c = -W_f Σ_s |goal_s - c_s| over their TOUCH_SENSORS, for random contacts."""
    w_f = AUTHORS[(task, "full")][1]
    params = reward_params.algorithm1(
        _demo(task), profiles.reward_weights("paper", task, "full", False)
    )
    rng = np.random.default_rng(0)
    contacts = (rng.uniform(size=(64, 15)) < 0.4).astype(np.float32)
    got = np.asarray(rewards.contact_reward(contacts, params.w_contact, params.contact_bias))
    goals = FORCE_GOALS[task]
    for c, r in zip(contacts, got):
        expected = -w_f * sum(abs(g - c[sh.sensor_index(s)]) for s, g in goals.items())
        assert r == pytest.approx(expected, abs=1e-6)
    assert got.max() <= 0.0


def test_paper_reward_is_never_positive_and_imitation_is_absolute():
    """Every term of the authors' reward is <= 0; their imitation weights do not scale with
    W_pos or W_ang (handshake baseline 2: W_ipos 1 x Algorithm 1's ratios, W_iang 0.2)."""
    from test_rewards import random_inputs

    weights = profiles.reward_weights("paper", "handshake", "baseline2", False)
    params = reward_params.algorithm1(_demo("handshake"), weights)
    ratios = np.asarray(params.w_position) / weights.K_p  # closest fingertip 1
    np.testing.assert_allclose(params.w_imitation_position, 1.0 * ratios, rtol=1e-6)
    np.testing.assert_allclose(params.w_imitation_angle, np.full(20, 0.2), rtol=1e-6)
    for task, reward in AUTHORS:
        weights = profiles.reward_weights("paper", task, reward, imitation=True)
        params = reward_params.algorithm1(_demo(task), weights)
        x = random_inputs(np.random.default_rng(1), (32,))
        x["contacts"] = (x["contacts"] > 0.5).astype(np.float32)
        terms = rewards.compute_rewards(params, np.zeros(32, np.int32), **x)
        assert float(np.max(terms["total"])) <= 0.0, (task, reward)


@pytest.mark.parametrize("task", ["handshake", "handclap", "et"])
def test_paper_learner_is_the_authors_ddpg_cycle_and_budget(task):
    config = train_config.preset("cpu", env=EnvConfig(profile="paper", task=task))
    d, T = config.ddpg, EPISODE[task]
    assert config.algo == "ddpg" and not d.layer_norm
    assert d.target_clip == (-T, 0.0)  # clip_return = 1/(1-gamma) = T, clip_pos_returns
    assert d.discount is None  # 1 - 1/T, their gamma
    collected = config.num_envs * d.unroll_length
    assert collected == 2 * T  # one cycle: rollout_batch_size 2 x T steps
    assert (d.updates_per_iteration, d.batch_size) == (40, 256)  # n_batches, batch_size
    assert d.iterations_per_epoch == 50  # n_cycles
    assert d.replay_capacity == 1_000_000 and d.polyak == 0.95 and d.action_l2 == 1.0
    assert config.epochs * collected * d.iterations_per_epoch == {100: 500_000, 75: 375_000}[T]
    assert config.eval_every == 5
    assert d.updates_per_iteration * d.batch_size / collected == pytest.approx(10240 / (2 * T))


@pytest.mark.parametrize("task", ["handshake", "handclap", "et"])
def test_paper_target_boxes_are_the_authors_ranges_along_their_slide_joints(task):
    """Offsets drawn by the environment, mapped back onto the authors' HMJX/Y/Z axes
    (world directions written out here), fill their training_range."""
    from mjx_hands import env as env_lib

    axes = {  # world directions of HMJX, HMJY, HMJZ: towards the agent, up, sideways
        "handshake": [(-1, 0, 0), (0, 0, 1), (0, 1, 0)],
        "handclap": [(-1, 0, 0), (0, 0, 1), (0, 1, 0)],
        "et": [(-0.878, 0, 0.479), (0, -1, 0), (0.479, 0, 0.878)],
    }[task]
    ranges = {
        "handshake": [(0, 0.05), (-0.05, 0.05), (0, 0.10)],
        "handclap": [(-0.05, 0.05), (-0.05, 0.05), (0, 0.15)],
        "et": [(0, 0.05), (-0.05, 0.05), (0.04, 0.17)],  # + U(0.04, 0.07) along HMJZ
    }[task]
    box = profiles.target_box("paper", task, (0.05, 0.05, 0.05))
    env = env_lib.HandInteractionEnv.__new__(env_lib.HandInteractionEnv)
    env.target_box = box
    offsets = np.asarray(jax.vmap(env._box_offset)(jax.random.split(jax.random.PRNGKey(0), 4000)))
    along = offsets @ np.linalg.pinv(np.array(axes, float).T).T  # coordinates on the axes
    for k, (lo, hi) in enumerate(ranges):
        assert along[:, k].min() >= lo - 1e-5 and along[:, k].max() <= hi + 1e-5
        assert along[:, k].min() < lo + 0.01 and along[:, k].max() > hi - 0.01
    if task == "et":  # a sum of two uniforms: its middle is denser than its ends
        middle = np.mean(np.abs(along[:, 2] - 0.105) < 0.02)
        assert middle > 0.4 / 1.3 * 1.05
    project = profiles.target_box("project", task, (0.05, 0.05, 0.05))
    assert project.low == (-0.05,) * 3 and project.high == (0.05,) * 3


def _contact_states(m: mujoco.MjModel, n: int = 32) -> list[mujoco.MjData]:
    """Poses in light contact, as training meets them: native handshake episodes whose
    hands close (fingers driven shut, arm held, with noise), every state with a phalanx
    within 2 mm of the other hand."""
    from mjx_hands import env as env_lib

    env = env_lib.make_env(
        "handshake", num_envs=n, profile="paper", mocap_source="synthetic", physics="native"
    )
    state = jax.jit(env.reset)(jax.random.PRNGKey(3))
    step = jax.jit(env.step)
    closing = np.concatenate([np.zeros((n, 4)), np.ones((n, 20))], 1).astype(np.float32)
    single, datas = env.unwrapped, []
    for i in range(12):
        noise = 0.3 * np.random.default_rng(i).normal(size=closing.shape).astype(np.float32)
        state = step(state, closing + noise)
        ps = state.pipeline_state
        near = np.asarray(jax.vmap(single.physics.readings)(ps).contacts).any(axis=1)
        for k in np.flatnonzero(near):
            d = mujoco.MjData(m)
            d.qpos[:], d.mocap_pos[:] = np.asarray(ps.qpos[k]), np.asarray(ps.mocap_pos[k])
            d.mocap_quat[:] = np.asarray(ps.mocap_quat[k])
            d.ctrl[:] = d.qpos[single.physics.actuated_qadr]  # the servos hold the pose
            datas.append(d)
    return datas


def test_mjx_touch_reading_matches_native_touch_sensors_in_contact():
    """The paper's contact rule: MuJoCo's touch sensors (force in the authors' palmar box
    sites) natively; in MJX, which has no sensor stage, a contact within the contact
    distance whose ray along its normal meets the site. On light contacts from closing
    hands both read the same sensors; native equals C MuJoCo's own sensors."""
    m = scene.build_model()
    mjx_physics = physics.MjxPhysics(m, 1, 0.002)
    native = physics.NativePhysics(m, 1, 0.002, threads=1)
    datas = _contact_states(m)
    qpos = np.stack([d.qpos for d in datas]).astype(np.float32)
    mocap_pos = np.stack([d.mocap_pos for d in datas]).astype(np.float32)
    mocap_quat = np.stack([d.mocap_quat for d in datas]).astype(np.float32)

    def touch(p):
        return jax.jit(jax.vmap(lambda q, x, r: p.readings(p.pose(q, x, r)).touch))(
            qpos, mocap_pos, mocap_quat
        )

    touch_mjx, touch_native = np.asarray(touch(mjx_physics)), np.asarray(touch(native))
    # Independent of both: C MuJoCo's touch sensors on the same poses (the model as the
    # native physics runs it: pair margins and gaps of contact_distance).
    reference = []
    for d in datas:
        mujoco.mj_forward(native.native_model, d)
        reference.append(d.sensordata[scene.SENSOR_LAYOUT.touch] > 0)
    reference = np.array(reference, np.float32)
    assert len(datas) >= 20 and reference.sum() >= 10  # a comparison with substance
    np.testing.assert_array_equal(touch_native, reference)
    agree = np.mean(touch_mjx == reference)
    recall = (touch_mjx * reference).sum() / reference.sum()
    precision = (touch_mjx * reference).sum() / max(touch_mjx.sum(), 1)
    # Measured: 402 of 405 readings agree; every native touch read by MJX, 3 extra.
    assert agree >= 0.98 and recall >= 0.9 and precision >= 0.75, (agree, recall, precision)


def test_paper_observation_is_joints_velocities_target_links_and_touch():
    """The authors' _get_obs: 28 joint angles, 28 velocities x dt, the 21 target-hand
    links in the world and the touch sensors; no goal, no time (134 values)."""
    from mjx_hands import env as env_lib

    env = env_lib.make_env(
        "et", num_envs=4, profile="paper", mocap_source="synthetic", physics="native"
    )
    state = jax.jit(env.reset)(jax.random.PRNGKey(0))
    state = jax.jit(env.step)(state, np.full((4, 24), 0.3, np.float32))
    obs = np.asarray(state.obs)
    assert obs.shape == (4, 134) and env.observation_size == 134
    single = env.unwrapped
    m = single.mj_model
    links = [n for n in scene.TARGET_LINKS if n not in ("forearm", "lfmetacarpal")]
    assert len(links) == 21  # the authors' ROBOT1_BODY_NAMES count
    for k in range(4):
        d = mujoco.MjData(m)
        ps = state.pipeline_state
        d.qpos[:], d.qvel[:] = np.asarray(ps.qpos[k]), np.asarray(ps.qvel[k])
        d.mocap_pos[:], d.mocap_quat[:] = np.asarray(ps.mocap_pos[k]), np.asarray(ps.mocap_quat[k])
        mujoco.mj_forward(m, d)
        link_pos = [d.xpos[m.body(scene.TARGET + n).id] for n in links]
        expected = np.concatenate(
            [
                d.qpos,
                0.04 * d.qvel,
                np.ravel(link_pos),
                np.asarray(ps.sensordata[k])[scene.SENSOR_LAYOUT.touch] > 0,
            ]
        )
        np.testing.assert_allclose(obs[k], expected, atol=2e-5)


def test_the_paper_profile_names_tasks_the_paper_did_not_study():
    from mjx_hands import tasks

    for task in tasks.TASKS:
        if not tasks.spec(task).in_authors_release:
            with pytest.raises(ValueError, match="paper did not study"):
                profiles.paper_weights(task, "full", True)

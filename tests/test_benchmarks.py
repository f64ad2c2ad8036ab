"""The benchmark scripts keep working (tiny sizes; no timing is asserted)."""

from __future__ import annotations

import json
from pathlib import Path

import jax
import mujoco
import numpy as np
import pytest
from mujoco import mjx

from benchmarks import replay as replay_bench
from mjx_hands.agents.ddpg import replay


def test_replay_benchmark_runs_both_buffers_at_capacity():
    assert replay_bench.ring_buffer_insert_seconds(256, 64, repeats=1) > 0
    assert replay_bench.brax_queue_insert_seconds(256, 64, repeats=1) > 0


def test_ring_buffer_full_insert_keeps_the_newest_capacity_transitions():
    """What the benchmark times is correct: after many inserts the buffer holds exactly
    the newest ``capacity`` transitions, in ring order."""
    batch = replay_bench._batch(64)
    numbered = batch.replace(reward=np.arange(64, dtype=np.float32))
    buffer = replay.create(100, jax.tree.map(lambda x: x[0], batch))
    for i in range(5):  # 320 transitions into 100 slots
        buffer = replay.insert(buffer, numbered.replace(reward=numbered.reward + 64 * i))
    ids = np.asarray(buffer.data.reward)
    assert sorted(ids) == list(range(220, 320))
    assert ids[int(buffer.position) - 1] == 319


@pytest.mark.slow
def test_throughput_quick_mode_runs_mjx_and_native_on_the_same_sequence(tmp_path):
    """--quick keeps benchmarks/throughput.py working in CI, and what it compares is
    comparable: from the same starts under the same set-points, MJX (float32) and
    native MuJoCo (float64) end 2 control steps (20 physics steps) in nearly the same pose."""
    from benchmarks import throughput

    out = tmp_path / "throughput.json"
    report = throughput.main(["--quick", "--out", str(out)])
    assert json.loads(out.read_text()) == report
    (result,) = report["results"]
    assert result["batch"] == 2 and result["finite"]
    assert set(result["compile_s"]) == {"physics"}  # starts from native MuJoCo: one compile
    assert result["physics_steps_per_s"] > 0 and result["native"]["physics_steps_per_s"] > 0
    assert result["max_qpos_gap_vs_native"] < 1e-4  # measured ~1e-7


def test_throughput_plot_from_the_recorded_results(tmp_path):
    from benchmarks import plot_throughput

    here = Path(plot_throughput.__file__).parent
    recorded = [
        here / "results_cpu.json",
        here / "results_gpu_h200.json",
        here / "results_gpu_h100.json",
    ]
    out = tmp_path / "throughput.png"
    plot_throughput.main([*map(str, recorded), "--out", str(out)])
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    broken = tmp_path / "broken.json"
    broken.write_text("{not json")
    with pytest.raises(SystemExit, match="broken.json"):
        plot_throughput.main([str(broken), "--out", str(out)])
    with pytest.raises(SystemExit, match="keys 'machine' and 'results'"):
        plot_throughput.main([str(here / "results_replay_cpu.json"), "--out", str(out)])


def test_cost_driver_variants_change_a_copy_of_the_model_only():
    from benchmarks import cost_drivers
    from mjx_hands import env as env_lib

    env = env_lib.make_env("handshake", mocap_source="synthetic", physics="mjx")
    iterations = env.mj_model.opt.iterations
    one = cost_drivers.variant_model(env, cost_drivers.VARIANTS["1 Newton iteration"])
    no_contacts = cost_drivers.variant_model(env, cost_drivers.VARIANTS["contacts disabled"])
    assert one.opt.iterations == 1 != iterations == env.mj_model.opt.iterations
    assert no_contacts.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    assert not env.mj_model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    # Contact rows are fixed when Data is made: the variant's states must be rebuilt.
    batch = jax.tree.map(lambda x: x[None], mjx.make_data(env.physics.mjx_model))
    assert batch._impl.ncon > 0
    rebuilt = cost_drivers.on_model(no_contacts, batch)
    assert rebuilt._impl.ncon == 0
    np.testing.assert_array_equal(rebuilt.qpos, batch.qpos)
    # A larger contact cap gives MJX room for more contacts; the env's model keeps its cap.
    cap = cost_drivers.variant_model(env, cost_drivers.VARIANTS["contact cap 24 pairs / 48 points"])
    assert cost_drivers.on_model(cap, batch)._impl.ncon > batch._impl.ncon
    cfg = env.config.scene
    assert env.mj_model.numeric("max_contact_points").data[0] == cfg.max_contact_points
    assert env.mj_model.numeric("max_geom_pairs").data[0] == cfg.max_geom_pairs
    with pytest.raises(SystemExit, match="unknown variants"):
        cost_drivers.main(["--variants", "as built,fewer fingers"])


@pytest.mark.slow
def test_time_to_target_stops_the_run_at_the_first_evaluation_that_reaches_it(tmp_path):
    """benchmarks/time_to_target.py times a real train.py launch and stops it once an
    evaluation reaches the target (0 here: the first), long before its epoch budget."""
    from benchmarks import first_epoch, time_to_target

    out = tmp_path / "time.json"
    tiny = [*first_epoch.SMALL, "--epochs", "200", "--checkpoint-every", "1"]
    time_to_target.main(
        [
            "--tasks",
            "handclap",
            "--algos",
            "ddpg-ln",
            "--target",
            "0",
            "--out",
            str(out),
            "--",
            *tiny,
        ]
    )
    record = json.loads(out.read_text())
    assert record["machine"]["backend"] == jax.default_backend()
    (row,) = record["results"]
    assert row["reached"] and row["epoch_at_target"] == 1
    assert 0 < row["minutes_to_target"] <= row["process_minutes"]
    assert row["curve"][0]["env_steps"] > 0
    assert row["curve"][-1]["epoch"] < 200  # stopped, not trained to the end


def test_machine_record_from_a_child_matches_this_process():
    """The child process (what launchers use, so they never hold the device) reports
    what this process does, and the throughput plot labels a record of that shape."""
    from benchmarks import machine, plot_throughput

    here = machine.describe()
    assert machine.describe_in_child() == here
    assert here["backend"] == jax.default_backend() and here["usable_cores"] >= 1
    assert machine.versions()["jax"] == jax.__version__
    assert machine.versions()["mujoco"] == mujoco.__version__
    label = plot_throughput.machine_label({"machine": here})
    cpu = here["device_kind"] == "cpu"
    assert label == (f"CPU, {here['cpu_count']} cores" if cpu else here["device_kind"])


def test_launcher_benchmarks_never_start_jax_in_their_own_process():
    """time_to_target and first_epoch time train.py in children; JAX in the parent would
    take a GPU's memory from the run being timed."""
    import subprocess
    import sys

    probe = (
        "import sys; from benchmarks import first_epoch, machine, time_to_target; "
        "machine.versions(); print('jax' in sys.modules, 'jaxlib' in sys.modules)"
    )
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run(
        [sys.executable, "-c", probe], cwd=root, capture_output=True, text=True, check=False
    )
    assert done.stdout.split() == ["False", "False"], done.stderr


def test_every_committed_results_table_equals_its_regeneration_from_records(capsys):
    """benchmarks/regenerate.py rebuilds each table listed in REPORTS from its grid
    records; a hand-edited table, or records changed without their table, fail here."""
    from benchmarks import regenerate

    code = regenerate.main(["--check"])
    assert code == 0, capsys.readouterr().out


def test_a_page_quoting_a_table_is_renewed_from_it_and_a_stale_quote_is_named(
    monkeypatch, tmp_path
):
    """A quote between the markers is replaced by its file whole; the prose around it stays;
    a quote that differs from its file, or of no file, is named by --check's helper."""
    from benchmarks import regenerate

    monkeypatch.setattr(regenerate, "ROOT", tmp_path)
    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "table.md").write_text("| a |\n|---|\n| 2 |\n")
    page = "before\n<!-- table: t/table.md -->\n| a |\n|---|\n| 1 |\n<!-- end table -->\nafter\n"
    (tmp_path / "page.md").write_text(page)
    assert regenerate.stale_quotes("page.md") == ["t/table.md"]
    renewed = regenerate.with_quotes_renewed(page)
    assert renewed == page.replace("| 1 |", "| 2 |")
    (tmp_path / "page.md").write_text(
        renewed + "<!-- table: t/gone.md -->\nx\n<!-- end table -->\n"
    )
    assert regenerate.stale_quotes("page.md") == ["t/gone.md"]
    with pytest.raises(ValueError, match="t/gone.md, which is not a file"):
        regenerate.with_quotes_renewed((tmp_path / "page.md").read_text())


def test_contact_hold_counts_the_steps_in_contact_after_the_first_and_the_changes():
    """Three hand-made episodes: held from step 2, patting on and off, never touching."""
    from benchmarks import contact_hold

    held = [0, 0, 1, 1, 1, 1, 1, 1]
    patting = [0, 1, 0, 1, 0, 1, 0, 1]
    never = [0] * 8
    stats = contact_hold.hold_statistics(np.array([held, patting, never], bool).T)
    assert stats["success_final"] == pytest.approx(2 / 3)
    assert stats["success_some_step"] == pytest.approx(2 / 3)
    assert stats["first_contact_step_median"] == 1.5  # steps 2 and 1
    assert stats["share_in_contact_after_first"] == pytest.approx((6 / 6 + 4 / 7) / 2)
    assert stats["contact_changes_median"] == 1.0  # 1, 7 and 0 changes
    assert stats["share_in_contact_last_10_steps"] == pytest.approx((6 + 4) / 24)


def test_the_privileged_lead_moves_the_palm_as_far_as_the_partner_goes_in_its_steps():
    """contact_hold's lead: the arm and wrist set-points sent move by a displacement whose
    forward kinematics carries the palm lead x period x the partner's true velocity (the
    chain's FK, independent of the IK that found it); the fingers' are the policy's, and
    lead 0 sends the policy's action unchanged."""
    import jax.numpy as jnp

    from benchmarks import contact_hold
    from mjx_hands import env as env_lib
    from mjx_hands import ik

    env = env_lib.make_env("et", mocap_source="synthetic", physics="native", target_speed=0.2)
    state = jax.jit(env.reset)(jax.random.PRNGKey(3))
    policy_action = jnp.asarray(np.random.default_rng(0).uniform(-0.5, 0.5, 24), jnp.float32)
    act = lambda obs: policy_action
    chain = env.chain
    arm = np.flatnonzero(np.isin(env.actuated_qadr, chain.qpos_adr))
    assert len(arm) == len(chain.qpos_adr) == 6  # arm and wrist, each with its actuator
    sent_plain = np.asarray(jax.jit(contact_hold.lead_step(env, act, 0))(state).pipeline_state.ctrl)
    np.testing.assert_allclose(sent_plain, np.asarray(env.ctrl_for(policy_action)), atol=1e-6)
    led = jax.jit(contact_hold.lead_step(env, act, 2))(state)
    shift = np.asarray(led.pipeline_state.ctrl) - np.asarray(env.ctrl_for(policy_action))
    fingers = np.setdiff1d(np.arange(24), arm)
    np.testing.assert_allclose(shift[fingers], 0.0, atol=1e-6)
    joints = np.asarray(state.pipeline_state.qpos)[chain.qpos_adr]
    moved = joints.copy()
    moved[[list(chain.qpos_adr).index(env.actuated_qadr[i]) for i in arm]] += shift[arm]
    before = np.asarray(ik.forward(chain, jnp.asarray(joints))[0])
    after = np.asarray(ik.forward(chain, jnp.asarray(moved))[0])
    expected = 2 * env.config.control_dt * np.asarray(state.info["episode"].target_velocity)
    assert np.linalg.norm(expected) == pytest.approx(0.016, rel=1e-4)  # 2 x 40 ms x 0.2 m/s
    np.testing.assert_allclose(after - before, expected, atol=1e-3)


def test_contact_gaps_are_the_nearest_sensed_phalanx_distance_to_the_partner():
    """contact_hold --gaps: E.T.'s one success group (the index distal phalanx) with the
    partner carried to a few millimetres' distance and pressed in, against MuJoCo's
    own geom-to-geom distance over that phalanx's pairs (mj_geomDistance)."""
    import mujoco

    from benchmarks import contact_hold
    from mjx_hands import env as env_lib
    from mjx_hands import physics, scene
    from mjx_hands import shadow_hand as sh

    env = env_lib.make_env("et", mocap_source="synthetic", physics="native")
    state = jax.jit(env.reset)(jax.random.PRNGKey(0))
    qpos = np.asarray(state.pipeline_state.qpos)
    groups = np.asarray(env.params.success_groups[0])
    model = physics.native_model(env.mj_model, contact_hold.GAP_LISTING)
    data = mujoco.MjData(model)
    sensed = model.geom(scene.AGENT + sh.hand_name("C_" + sh.PHALANX_BODY[("ff", "distal")])).id
    partners = model.pair_geom2[model.pair_geom1 == sensed]
    assert partners.size > 0
    tip = np.asarray(state.info["episode"].target_points)[sh.HAND_POINTS.index("fftip")]
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    agent_tip = data.site(scene.AGENT + sh.hand_name("S_fftip")).xpos.copy()
    seen = []
    for offset in (0.012, 0.006, 0.0, -0.004):  # partner's fingertip carried onto the agent's
        mocap_pos = np.asarray(state.pipeline_state.mocap_pos).copy()
        away = agent_tip - tip
        mocap_pos[env.target_mocap] += away + offset * np.array([0.0, 0.0, 1.0])
        mocap_quat = np.asarray(state.pipeline_state.mocap_quat)
        gap = contact_hold.group_gaps(env.mj_model, qpos[None], mocap_pos[None],
                                      mocap_quat[None], groups)[0]  # fmt: skip
        data.qpos[:], data.mocap_pos[:], data.mocap_quat[:] = qpos, mocap_pos, mocap_quat
        mujoco.mj_forward(model, data)
        expected = min(mujoco.mj_geomDistance(model, data, sensed, g, contact_hold.GAP_LISTING, None)
                       for g in partners)  # fmt: skip
        if expected < contact_hold.GAP_LISTING:
            assert gap == pytest.approx(expected, abs=2e-4)
            seen.append(gap)
        else:
            assert gap == np.inf
    assert len(seen) >= 2 and min(seen) < 0.002  # near and touching cases were exercised


def test_carried_contacts_keep_the_palm_pose_relative_to_a_turned_target():
    """reachability --carry: the palm's pose relative to the target palm (a NumPy
    transcription of the frame change) is the same after the target turns 5 deg and the
    arm is solved for it, as where it started (this start is clear of the joint limits); and the contact check's success is the
    index distal phalanx's MuJoCo geom distance within the contact distance."""
    import jax.numpy as jnp
    import mujoco

    from benchmarks import reachability
    from mjx_hands import env as env_lib
    from mjx_hands import ik, physics, scene
    from mjx_hands import shadow_hand as sh

    env = env_lib.make_env("et", mocap_source="synthetic", physics="native")
    key = jax.random.PRNGKey(1)
    start = env.reset_with(key, jnp.array([1.0, 0.0, 0.0, 0.0]))
    q = start.pipeline_state.qpos[env.chain.qpos_adr]
    pos, rot = ik.forward(env.chain, q)
    episode = start.info["episode"]
    rel_pos, rel_rot = reachability.relative_pose(pos, rot, episode.target_pos, episode.target_rot)
    frame = np.asarray(episode.target_rot, np.float64)
    np.testing.assert_allclose(rel_pos, frame.T @ np.asarray(pos - episode.target_pos), atol=1e-6)
    np.testing.assert_allclose(rel_rot, frame.T @ np.asarray(rot), atol=1e-6)
    turned = env.reset_with(key, env_lib.yaw_pitch_quat(np.radians(5.0), 0.0)).info["episode"]
    arm = reachability.carried_arm(env.chain, rel_pos, rel_rot, turned.target_pos,
                                   turned.target_rot, q, jax.random.PRNGKey(2), 2, 100, 1.0)  # fmt: skip
    assert np.all((arm >= env.chain.lower - 1e-6) & (arm <= env.chain.upper + 1e-6))
    new_pos, new_rot = ik.forward(env.chain, arm)
    turned_frame = np.asarray(turned.target_rot, np.float64)
    np.testing.assert_allclose(turned_frame.T @ np.asarray(new_pos - turned.target_pos),
                               np.asarray(rel_pos), atol=1e-4)  # fmt: skip
    np.testing.assert_allclose(turned_frame.T @ np.asarray(new_rot), np.asarray(rel_rot), atol=1e-3)

    model = physics.native_model(env.mj_model, env.config.contact_distance)
    data = mujoco.MjData(model)
    sensed = model.geom(scene.AGENT + sh.hand_name("C_" + sh.PHALANX_BODY[("ff", "distal")])).id
    partners = model.pair_geom2[model.pair_geom1 == sensed]
    groups = np.asarray(env.params.success_groups[0])
    qpos = np.asarray(start.pipeline_state.qpos)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    agent_tip = data.site(scene.AGENT + sh.hand_name("S_fftip")).xpos.copy()
    tip = np.asarray(episode.target_points)[sh.HAND_POINTS.index("fftip")]
    verdicts = set()
    for offset in (0.2, 0.005, 0.0, -0.003):  # far away, near, touching, pressed
        mocap_pos = np.asarray(start.pipeline_state.mocap_pos).copy()
        mocap_pos[env.target_mocap] += agent_tip - tip + offset * np.array([0.0, 0.0, 1.0])
        mocap_quat = np.asarray(start.pipeline_state.mocap_quat)
        ok, depth = reachability.contact_check(model, data, qpos, mocap_pos, mocap_quat, groups,
                                               env.config.contact_distance)  # fmt: skip
        data.qpos[:], data.mocap_pos[:], data.mocap_quat[:] = qpos, mocap_pos, mocap_quat
        mujoco.mj_forward(model, data)
        nearest = min(mujoco.mj_geomDistance(model, data, sensed, g, 0.05, None) for g in partners)
        assert ok == (nearest < env.config.contact_distance)
        assert depth >= max(-nearest, 0.0) - 2e-4  # the deepest contact, of any geom
        verdicts.add(ok)
    assert verdicts == {True, False}


def oracle_start():
    """(env, state (time, qpos, qvel) (1, ...), mocap poses (1, ...), actuated joints (1,
    nu), ctrl ranges lo/hi (nu,)) of E.T.'s start at rest on native MuJoCo, float64."""
    from mjx_hands import env as env_lib

    env = env_lib.make_env("et", mocap_source="synthetic", physics="native")
    ps = jax.jit(env.reset)(jax.random.PRNGKey(0)).pipeline_state
    qpos = np.asarray(ps.qpos, np.float64)[None]
    state = (np.zeros(1), qpos, np.zeros((1, env.mj_model.nv)))
    mocap = (np.asarray(ps.mocap_pos)[None], np.asarray(ps.mocap_quat)[None])
    ranges = (np.asarray(env.ctrl_lo, np.float64), np.asarray(env.ctrl_hi, np.float64))
    return env, state, mocap, qpos[:, env.actuated_qadr], ranges


def test_the_oracle_brings_the_joints_to_a_state_reached_in_one_period_where_the_goal_lags():
    """contact_oracle.choose_setpoints: from E.T.'s start at rest, asked for the joints and
    velocities that some hidden set-points (a few centiradians from the start, in range)
    reach in one period of native MuJoCo, it picks set-points whose period ends at least 4
    times nearer those joints than sending the goal joints themselves as set-points (the
    servos lag, about 0.15 s), within the actuators' ranges."""
    from benchmarks import contact_oracle

    env, state, mocap, start, (lo, hi) = oracle_start()
    physics, adr = env.physics, env.actuated_qadr
    hidden = np.clip(start + np.random.default_rng(0).uniform(-0.15, 0.15, start.shape), lo, hi)
    period = lambda ctrl: physics.run(*state, ctrl, *mocap, nstep=physics.n_substeps)
    goal_q, goal_qd = (np.asarray(x, np.float64)[:, adr] for x in period(hidden)[:2])
    assert np.abs(goal_q - start).max() > 0.02  # the hidden set-points move the joints
    chosen = contact_oracle.choose_setpoints(physics, state, mocap, start.copy(),
                                             contact_oracle.joint_residuals(goal_q, goal_qd, adr), lo, hi)  # fmt: skip
    assert np.all((chosen >= lo - 1e-9) & (chosen <= hi + 1e-9))
    error = {
        name: np.abs(np.asarray(period(ctrl)[0])[:, adr] - goal_q).max()
        for name, ctrl in (("oracle", chosen), ("goal as set-point", np.clip(goal_q, lo, hi)))
    }
    assert error["goal as set-point"] > 0.01  # the lag the oracle must compensate
    assert error["oracle"] < error["goal as set-point"] / 4, error


def test_the_oracle_brings_the_hand_points_to_where_hidden_setpoints_carry_them():
    """contact_oracle.hand_residuals: asked for the palm centre and fingertips (the
    environment's own point sensors) that hidden set-points reach in one period, with the
    start's joints as the light regulariser, the oracle's period ends at least 4 times
    nearer those points than staying put; the points are native MuJoCo's site positions."""
    from benchmarks import contact_oracle
    from mjx_hands import scene
    from mjx_hands import shadow_hand as sh

    env, state, mocap, start, (lo, hi) = oracle_start()
    physics, adr = env.physics, env.actuated_qadr
    hidden = np.clip(start + np.random.default_rng(1).uniform(-0.15, 0.15, start.shape), lo, hi)
    period = lambda ctrl: [np.asarray(x, np.float64) for x in physics.run(*state, ctrl, *mocap,
                                                                          nstep=physics.n_substeps)]  # fmt: skip
    q, _, _, sensordata = period(hidden)
    data = mujoco.MjData(env.physics.native_model)
    data.qpos[:], data.mocap_pos[:], data.mocap_quat[:] = q[0], mocap[0][0], mocap[1][0]
    mujoco.mj_forward(env.physics.native_model, data)
    tip = data.site(scene.AGENT + sh.hand_name("S_fftip")).xpos
    points = sensordata[:, scene.SENSOR_LAYOUT.points].reshape(1, -1, 3)
    # mj_step reads its sensors before the last substep's integration: 4 ms behind qpos.
    np.testing.assert_allclose(points[0, sh.HAND_POINTS.index("fftip")], tip, atol=2e-3)
    residuals = contact_oracle.hand_residuals(points, start, np.zeros_like(start), adr)
    chosen = contact_oracle.choose_setpoints(physics, state, mocap, start.copy(), residuals, lo, hi)
    assert np.all((chosen >= lo - 1e-9) & (chosen <= hi + 1e-9))
    miss = lambda ctrl: np.abs(period(ctrl)[3][:, scene.SENSOR_LAYOUT.points] - points.reshape(1, -1)).max()
    assert miss(start) > 0.005  # the hidden set-points move the points
    assert miss(chosen) < miss(start) / 4, (miss(chosen), miss(start))


def test_the_oracle_weights_the_tips_of_the_fingers_its_success_groups_name():
    """contact_oracle.contact_point_weights: E.T. (index distal) weights the index tip
    alone, the clap (four fingers' distal and middle phalanges) those four tips, never the
    palm centre or a finger no group names."""
    from benchmarks import contact_oracle
    from mjx_hands import reward_params
    from mjx_hands import shadow_hand as sh

    for task, weighted in (("et", {"fftip"}), ("handclap", {"fftip", "mftip", "rftip", "lftip"})):
        weights = contact_oracle.contact_point_weights(np.asarray(reward_params.success_group_mask(task)), 7.0)
        assert {p for p, w in zip(sh.HAND_POINTS, weights) if w == 7.0} == weighted
        assert all(w == 1.0 for p, w in zip(sh.HAND_POINTS, weights) if p not in weighted)


def test_the_oracle_scores_success_as_the_geom_distance_within_the_contact_distance():
    """contact_oracle.success_of on the readings native MuJoCo computes at a pose (the
    environment's own sensors) is the index distal phalanx's MuJoCo geom distance to the
    partner within the contact distance (E.T.'s success group), far, near and pressed."""
    import mujoco

    from benchmarks import contact_oracle
    from mjx_hands import env as env_lib
    from mjx_hands import physics, scene
    from mjx_hands import shadow_hand as sh

    env = env_lib.make_env("et", mocap_source="synthetic", physics="native")
    start = jax.jit(env.reset)(jax.random.PRNGKey(1))
    qpos = np.asarray(start.pipeline_state.qpos)
    model = physics.native_model(env.mj_model, env.config.contact_distance)
    data = mujoco.MjData(model)
    sensed = model.geom(scene.AGENT + sh.hand_name("C_" + sh.PHALANX_BODY[("ff", "distal")])).id
    partners = model.pair_geom2[model.pair_geom1 == sensed]
    groups = np.asarray(env.params.success_groups[0])
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    agent_tip = data.site(scene.AGENT + sh.hand_name("S_fftip")).xpos.copy()
    tip = np.asarray(start.info["episode"].target_points)[sh.HAND_POINTS.index("fftip")]
    verdicts = set()
    for offset in (0.2, 0.006, 0.0, -0.003):  # far away, near, touching, pressed
        mocap_pos = np.asarray(start.pipeline_state.mocap_pos).copy()
        mocap_pos[env.target_mocap] += agent_tip - tip + offset * np.array([0.0, 0.0, 1.0])
        mocap_quat = np.asarray(start.pipeline_state.mocap_quat)
        readings = env.physics.pose(qpos, mocap_pos, mocap_quat).sensordata
        ok = contact_oracle.success_of(np.asarray(readings)[None], groups,
                                       env.config.contact_distance)[0]  # fmt: skip
        data.qpos[:], data.mocap_pos[:], data.mocap_quat[:] = qpos, mocap_pos, mocap_quat
        mujoco.mj_forward(model, data)
        nearest = min(mujoco.mj_geomDistance(model, data, sensed, g, 0.05, None) for g in partners)
        assert ok == (nearest < env.config.contact_distance), (offset, nearest)
        verdicts.add(bool(ok))
    assert verdicts == {True, False}


def test_the_oracle_carries_the_rest_palm_pose_by_the_partner_displacement():
    """contact_oracle.carried_joints: the chain's forward kinematics of the joints it gives
    puts the palm at its rest position plus the partner's displacement, with the rest
    orientation, a few centimetres each way from a pose clear of the joint limits."""
    import jax.numpy as jnp

    from benchmarks import contact_oracle
    from mjx_hands import env as env_lib
    from mjx_hands import ik

    env = env_lib.make_env("et", mocap_source="synthetic", physics="native")
    chain = env.chain
    rest = (0.5 * (chain.lower + chain.upper))[None]  # clear of the limits, each way
    shifts = np.array([[0.0, 0.0, 0.0], [0.02, 0.0, 0.0], [0.02, -0.02, 0.01], [0.0, 0.01, -0.02]])
    carried, error = contact_oracle.carried_joints(chain, rest, shifts[:, None])
    pos0, rot0 = (np.asarray(x) for x in ik.forward(chain, jnp.asarray(rest[0])))
    for shift, joints in zip(shifts, carried[:, 0]):
        pos, rot = (np.asarray(x) for x in ik.forward(chain, jnp.asarray(joints)))
        np.testing.assert_allclose(pos, pos0 + shift, atol=1e-3)
        np.testing.assert_allclose(rot, rot0, atol=1e-2)
    np.testing.assert_allclose(error, 0.0, atol=1e-3)  # reached, and said so


def test_the_reactive_oracle_extrapolates_the_partner_at_its_last_velocity():
    """contact_oracle.seen_partner: the prescient oracle sees the true path; the reactive
    one, at rest before the first step, each next pose one step's last displacement on,
    which misses a turn by exactly the change of displacement."""
    from benchmarks import contact_oracle

    steps = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 2.0], [0.0, 2.0]])
    path = np.cumsum(steps, axis=0)[:, None]  # (T+1, 1 episode, 2)
    assert contact_oracle.seen_partner(path, True) is path
    seen = contact_oracle.seen_partner(path, False)
    expected = [path[0], path[0], path[1] + steps[1], path[2] + steps[2], path[3] + steps[3]]
    np.testing.assert_allclose(seen, np.stack(expected))
    np.testing.assert_allclose(seen[3, 0] - path[3, 0], steps[2] - steps[3])  # the turn, unforeseen


def test_the_oracle_keeps_a_rest_pose_pressed_past_a_joint_limit_where_the_partner_rests():
    """contact_oracle.carried_joints from a wrist pressed past its limit (as a contact
    presses it): with no displacement, the rest joints exactly (an IK that clips to the
    limits would move them), and where a displacement needs that joint further past it,
    the palm error it reports is the forward kinematics' distance from the carried goal."""
    import jax.numpy as jnp

    from benchmarks import contact_oracle
    from mjx_hands import env as env_lib
    from mjx_hands import ik

    env = env_lib.make_env("et", mocap_source="synthetic", physics="native")
    chain = env.chain
    rest = 0.5 * (chain.lower + chain.upper)
    rest[4] = chain.upper[4] + 0.01  # WRJ1, 10 mrad past its upper limit
    carried, error = contact_oracle.carried_joints(chain, rest[None], np.array([[[0.0, 0.0, 0.0]],
                                                                                [[0.01, 0.0, 0.0]]]))  # fmt: skip
    np.testing.assert_allclose(carried[0, 0], rest, atol=1e-6)
    assert error[0, 0] < 1e-5
    pos0 = np.asarray(ik.forward(chain, jnp.asarray(rest))[0])
    pos1 = np.asarray(ik.forward(chain, jnp.asarray(carried[1, 0]))[0])
    assert error[1, 0] == pytest.approx(np.linalg.norm(pos1 - pos0 - [0.01, 0.0, 0.0]), abs=1e-4)

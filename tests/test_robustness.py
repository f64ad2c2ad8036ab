"""Robustness sweeps: the turned target and the moving target, against NumPy references."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from mjx_hands import env as env_lib
from mjx_hands import robustness, scene

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0], np.float32)


def rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


@pytest.fixture(scope="module")
def moving_env():
    """A handshake env (native physics, compiles in seconds) whose target can move."""
    env = env_lib.make_env(
        "handshake",
        mocap_source="synthetic",
        physics="native",
        target_speed=0.0,
        target_motion_box=(0.3, 0.3, 0.3),
    )
    return env, jax.jit(jax.vmap(env.reset_with)), jax.jit(jax.vmap(env.step))


def test_yaw_pitch_turns_the_target_hand_its_goals_and_its_mocap_bodies(moving_env):
    env, reset, _ = moving_env
    yaw, pitch = np.radians([0.0, 30.0, -45.0, 60.0]), np.radians([0.0, -20.0, 45.0, 60.0])
    tilts = jax.vmap(env_lib.yaw_pitch_quat)(yaw, pitch)
    key = jax.random.split(jax.random.PRNGKey(7), 1)
    keys = jnp.repeat(key, 4, axis=0)  # the same episode, turned four ways
    state = reset(keys, tilts, jnp.zeros(4))
    ep = state.info["episode"]
    nominal = np.asarray(env.target_rot)
    pos0 = np.asarray(ep.target_pos[0])
    goal0 = np.asarray(ep.goal_points[0]) - pos0
    for i in range(4):
        turn = rot_z(yaw[i]) @ rot_y(pitch[i])
        np.testing.assert_allclose(np.asarray(ep.target_rot[i]), turn @ nominal, atol=2e-5)
        # Turned about the palm centre: it stays, the goals turn about it.
        np.testing.assert_allclose(np.asarray(ep.target_pos[i]), pos0, atol=1e-6)
        goals = np.asarray(ep.goal_points[i]) - pos0
        np.testing.assert_allclose(goals, goal0 @ turn.T, atol=2e-5)
        # The rendered/simulated target hand is where the frame says.
        d = mujoco.MjData(env.mj_model)
        d.mocap_pos[:] = np.asarray(state.pipeline_state.mocap_pos[i])
        d.mocap_quat[:] = np.asarray(state.pipeline_state.mocap_quat[i])
        mujoco.mj_kinematics(env.mj_model, d)
        body = env.mj_model.body(scene.TARGET + "palm").id
        np.testing.assert_allclose(d.xmat[body].reshape(3, 3), turn @ nominal, atol=2e-5)
    # Untilted and at speed 0, reset_with is the plain reset of the same key.
    plain = jax.jit(env.reset)(key[0])
    np.testing.assert_allclose(np.asarray(state.obs[0]), np.asarray(plain.obs), atol=1e-6)


def test_moving_target_keeps_its_speed_turns_every_half_second_and_carries_the_goals(
    moving_env,
):
    env, reset, step = moving_env
    n, steps, dt = 3, 40, env.config.control_dt
    speeds = np.array([0.0, 0.1, 0.25], np.float32)
    state = reset(jax.random.split(jax.random.PRNGKey(1), n), jnp.tile(IDENTITY, (n, 1)), speeds)
    record = {k: [] for k in ("pos", "goals", "points", "mocap")}
    for t in range(steps + 1):
        ep = state.info["episode"]
        record["pos"].append(np.asarray(ep.target_pos))
        record["goals"].append(np.asarray(ep.goal_points))
        record["points"].append(np.asarray(ep.target_points))
        record["mocap"].append(np.asarray(state.pipeline_state.mocap_pos))
        if t < steps:
            state = step(state, jnp.zeros((n, env.action_size)))
    pos = np.array(record["pos"])  # (T+1, n, 3)
    moves = np.diff(pos, axis=0)  # (T, n, 3)
    np.testing.assert_allclose(
        np.linalg.norm(moves, axis=-1), np.tile(speeds * dt, (steps, 1)), atol=1e-6
    )
    # Directions change exactly at the steps where (k + 1)·dt enters a new 0.5 s period.
    k = np.arange(steps)
    expected = np.floor((k + 1) * dt / 0.5 + 1e-6) > np.floor(k * dt / 0.5 + 1e-6)
    for i in (1, 2):
        unit = moves[:, i] / np.linalg.norm(moves[:, i], axis=-1, keepdims=True)
        turned = np.r_[False, (unit[1:] * unit[:-1]).sum(-1) < 1 - 1e-6]
        np.testing.assert_array_equal(turned[1:], expected[1:])
    # Goals, target points and every mocap body of the target move with the palm.
    for key in ("goals", "points"):
        shifts = np.diff(np.array(record[key]), axis=0)
        np.testing.assert_allclose(shifts, np.repeat(moves[:, :, None], 6, axis=2), atol=1e-6)
    mocap = np.diff(np.array(record["mocap"]), axis=0)[:, :, env.target_mocap]
    np.testing.assert_allclose(
        mocap, np.repeat(moves[:, :, None], len(env.target_mocap), 2), atol=1e-6
    )


def test_moving_target_bounces_inside_its_box_at_constant_speed():
    center, half = np.zeros(3, np.float32), np.full(3, 0.02, np.float32)
    rng = np.random.default_rng(0)
    position = rng.uniform(-0.02, 0.02, (200, 3)).astype(np.float32)
    velocity = rng.normal(size=(200, 3)).astype(np.float32) * 0.3
    step = jax.jit(jax.vmap(lambda p, v: env_lib.reflect_into_box(p + 0.04 * v, v, center, half)))
    new_p, new_v = map(np.asarray, step(position, velocity))
    assert np.all(np.abs(new_p) <= 0.02 + 1e-7)
    np.testing.assert_allclose(np.linalg.norm(new_v, axis=1), np.linalg.norm(velocity, axis=1))
    # NumPy reference: mirror each coordinate at the wall it crossed.
    raw = position + 0.04 * velocity
    ref = np.where(raw > 0.02, 0.04 - raw, np.where(raw < -0.02, -0.04 - raw, raw))
    np.testing.assert_allclose(new_p, ref, atol=1e-7)
    np.testing.assert_array_equal(np.sign(new_v) != np.sign(velocity), np.abs(raw) > 0.02)


def test_a_static_target_has_no_motion_and_refuses_a_speed():
    env = env_lib.make_env("et", mocap_source="synthetic", physics="native")
    state = jax.eval_shape(env.reset, jax.random.PRNGKey(0))
    assert state.info["episode"].target_velocity is None
    with pytest.raises(ValueError, match="needs a moving target"):
        env.reset_with(jax.random.PRNGKey(0), None, jnp.float32(0.1))
    with pytest.raises(ValueError, match="target_speed -1"):
        env_lib.make_env("et", mocap_source="synthetic", physics="native", target_speed=-1.0)


def test_angle_grid_and_bad_options():
    np.testing.assert_allclose(robustness.angle_grid(60, 15), np.arange(-60, 61, 15))
    np.testing.assert_allclose(robustness.angle_grid(50, 20), [-40, -20, 0, 20, 40])
    np.testing.assert_allclose(robustness.angle_grid(0, 15), [0])
    args = robustness.RobustnessArgs(run_dirs=("a", "b"), speeds=(-0.1,), angle_step_deg=0)
    with pytest.raises(ValueError) as err:
        robustness.check_args(args)
    for text in ("--out DIR", "--speeds", "--angle-step-deg"):
        assert text in str(err.value)


def _write_sweeps(folder, rng, runs: int, episodes: int, natural: list[float] | None):
    """Robustness records as `robustness --sweep all` writes them, of random per-run rates."""
    import json

    folder.mkdir(parents=True)
    angles = robustness.angle_grid(60.0, 15.0)
    common = {"task": "et", "runs": runs, "episodes": episodes}
    per_run = lambda *shape: [rng.uniform(0, 1, shape) for _ in range(runs)]
    sweeps = {
        robustness.ORIENTATION_FILE: ({"angles_deg": angles.tolist()}, {"success_final": (9, 9)}),
        robustness.MOTION_FILE: ({"speeds": [0.0, 0.2]}, {"success_final": (2,)}),
        robustness.PARTNER_FILE: (
            {"conditions": ["static", "recorded, share 0.5"]},
            {"success_final": (2,)},
        ),
        robustness.SENSING_FILE: (
            {"noise_mm": [0.0, 5.0], "delays": [0, 1]},
            {"noise_success_final": (2,), "delay_success_final": (2,)},
        ),
    }
    truth = {}
    for name, (extra, keys) in sweeps.items():
        values = {key: per_run(*shape) for key, shape in keys.items()}
        summary = common | extra | robustness.combine(
            [{k: v[r] for k, v in values.items()} for r in range(runs)], episodes
        )
        (folder / f"{name}.json").write_text(json.dumps(summary))
        truth[name] = {k: np.stack(v) for k, v in values.items()}
    if natural is not None:
        policies = [{"dtw": d, "jerk": 2 * d} for d in natural]
        (folder / "naturalness.json").write_text(json.dumps({"policies": policies}))
    return angles, truth


def test_the_side_by_side_report_averages_regions_and_runs_as_numpy_does(tmp_path):
    import json

    from mjx_hands import partner_report

    rng = np.random.default_rng(0)
    _, static = _write_sweeps(tmp_path / "static", rng, 1, 32, None)
    _, robust = _write_sweeps(tmp_path / "robust", rng, 3, 32, [0.1, 0.2, 0.4])
    _write_sweeps(tmp_path / "single", rng, 1, 32, [0.3])
    argv = ["static=" + str(tmp_path / "static"), "robust=" + str(tmp_path / "robust"),
            "single=" + str(tmp_path / "single")]
    assert partner_report.main([*argv, "--out", str(tmp_path / "out")]) == 0
    report = json.loads((tmp_path / "out" / "side_by_side.json").read_text())
    rows = {r["condition"]: r for r in report["rows"]}
    # Within +-30 deg: the 5 x 5 centre cells; 3 runs: mean and SE over runs.
    grids = robust[robustness.ORIENTATION_FILE]["success_final"]  # (3, 9, 9)
    per_run = grids[:, 2:7, 2:7].mean(axis=(1, 2))
    np.testing.assert_allclose(
        rows["yaw x pitch within +-30 deg"]["robust"],
        [per_run.mean(), per_run.std(ddof=1) / np.sqrt(3)],
    )
    # One run: the binomial error over every episode of the region.
    one = static[robustness.ORIENTATION_FILE]["success_final"][0]
    p = one[1:8, 1:8].mean()
    np.testing.assert_allclose(
        rows["yaw x pitch within +-45 deg"]["static"], [p, np.sqrt(p * (1 - p) / (32 * 49))]
    )
    np.testing.assert_allclose(rows["nominal pose"]["static"][0], one[4, 4])
    speeds = robust[robustness.MOTION_FILE]["success_final"][:, 1]
    np.testing.assert_allclose(rows["moving at 0.2 m/s"]["robust"][0], speeds.mean())
    partner = robust[robustness.PARTNER_FILE]["success_final"][:, 1]
    np.testing.assert_allclose(rows["recorded, share 0.5 partner"]["robust"][0], partner.mean())
    delay = static[robustness.SENSING_FILE]["delay_success_final"][0, 1]
    np.testing.assert_allclose(rows["action delay 1 step(s)"]["static"][0], delay)
    np.testing.assert_allclose(rows["naturalness: jerk"]["robust"][0], 2 * 0.7 / 3)
    assert rows["naturalness: dtw"]["static"] is None  # not measured for that setup
    assert rows["naturalness: dtw"]["single"] == [0.3, None]  # one policy: no spread
    text = (tmp_path / "out" / "side_by_side.md").read_text()
    assert text.splitlines()[0] == "| et: condition | static | robust | single |"
    assert "| naturalness: dtw |  | 0.2333 ± 0.08819 | 0.3 (n = 1) |" in text
    assert (tmp_path / "out" / "orientation_side_by_side.png").stat().st_size > 10_000
    # Folders pooled (seeds swept apart): the runs of both, as one setup of 4 runs.
    pooled = "pooled=" + str(tmp_path / "robust") + "," + str(tmp_path / "single")
    assert partner_report.main([pooled, "--out", str(tmp_path / "pool")]) == 0
    rows = {r["condition"]: r for r in
            json.loads((tmp_path / "pool" / "side_by_side.json").read_text())["rows"]}
    single = json.loads((tmp_path / "single" / f"{robustness.MOTION_FILE}.json").read_text())
    speeds = np.concatenate([robust[robustness.MOTION_FILE]["success_final"][:, 1],
                             np.asarray(single["success_final_per_run"])[:, 1]])
    np.testing.assert_allclose(
        rows["moving at 0.2 m/s"]["pooled"], [speeds.mean(), speeds.std(ddof=1) / 2.0]
    )
    np.testing.assert_allclose(rows["naturalness: dtw"]["pooled"][0], (0.1 + 0.2 + 0.4 + 0.3) / 4)
    (tmp_path / "single" / "naturalness.json").unlink()
    assert partner_report.main([pooled, "--out", str(tmp_path / "pool")]) == 2  # only some
    # Bad input is named.
    assert partner_report.main(["static", "--out", str(tmp_path / "x")]) == 2
    assert partner_report.main(["a=" + str(tmp_path), "--out", str(tmp_path / "x")]) == 2


def test_the_training_cost_row_times_the_first_evaluation_at_the_mark_after_a_resume(tmp_path):
    """Minutes to 0.9 at the end: a static run, its robust continuation (same first rows,
    NaN where no episode ended) and a longer robust run resumed from that, read from
    metrics.csv and config.json as a reader would by hand."""
    import csv
    import json

    from mjx_hands import partner_report

    def write(folder, evals, partners, epoch_seconds=60.0):  # evals: per epoch, or None
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "config.json").write_text(json.dumps({"partners": partners}))
        with (folder / "metrics.csv").open("w", newline="") as f:
            out = csv.writer(f)
            out.writerow(["epoch", "time/wall_seconds", "train/success", "eval/success_final"])
            for epoch, value in enumerate(evals, start=1):
                ended = "nan" if epoch % 2 else 0.5  # no episode ended in odd epochs
                out.writerow([epoch, epoch_seconds * epoch, ended, "" if value is None else value])

    rng = np.random.default_rng(1)
    static = [None, 0.5, None, 0.95, None, 1.0]  # reaches 0.9 at epoch 4: 4 minutes
    robust_stage = [None, 0.6, 0.92, 0.97]  # against its own partners: epoch 9
    early = [0.1, 0.2, 0.91, 1.0, 1.0, 1.0]  # seed 1: 3 minutes, and never after its resume
    runs = [
        (static, static + robust_stage, static + robust_stage + [1.0, 1.0]),
        (early, early + [0.5, 0.6, 0.7, 0.8], early + [0.5, 0.6, 0.7, 0.8, 0.5, 0.95]),
    ]
    seeds = {}
    for seed, evals in enumerate(runs):
        for label, partners, values in zip(("static", "curriculum", "longer"),
                                           ("static", "robust", "robust"), evals):  # fmt: skip
            folder = tmp_path / f"seed{seed}" / label
            _write_sweeps(folder, rng, 1, 32, None)
            write(folder, values, partners)
            seeds.setdefault(label, []).append(str(folder))
    argv = [f"{label}={','.join(folders)}" for label, folders in seeds.items()]
    assert partner_report.main([*argv, "--out", str(tmp_path / "out")]) == 0
    rows = {
        r["condition"]: r
        for r in json.loads((tmp_path / "out" / "side_by_side.json").read_text())["rows"]
    }
    row = rows[partner_report.TRAINING_ROW]
    # Static: epochs 4 and 3; curriculum: epoch 9 (seed 0), seed 1 never after its resume
    # at epoch 6 (the 0.91 at epoch 3 was the static stage's); the longer run's stage
    # starts where the partners changed (epoch 6, not the curriculum's 10): 9 and 12.
    np.testing.assert_allclose(row["static"][:2], [3.5, np.std([4.0, 3.0], ddof=1) / np.sqrt(2)])
    assert row["static"][2:] == [2, 2]
    assert row["curriculum"] == [9.0, None, 1, 2]
    np.testing.assert_allclose(row["longer"][:2], [10.5, 1.5])
    text = (tmp_path / "out" / "side_by_side.md").read_text()
    assert f"| {partner_report.TRAINING_ROW} | 3.5 ± 0.5 | 9.0 (n = 1); 1 of 2 reached it |" in text
    # Without the static column the curriculum still counts from its sibling static run's
    # end (the seeds' folder layout), not from the static stage's 0.9.
    alone = [f"curriculum={','.join(seeds['curriculum'])}", "--out", str(tmp_path / "alone")]
    assert partner_report.main(alone) == 0
    rows = json.loads((tmp_path / "alone" / "side_by_side.json").read_text())["rows"]
    assert {r["condition"]: r for r in rows}[partner_report.TRAINING_ROW]["curriculum"] == [
        9.0, None, 1, 2,
    ]  # fmt: skip
    # A stage resumed from a retrained static run (the same evaluations, other timings):
    # still counted from the static stage's end, on its own clock (90 s an epoch).
    again = tmp_path / "seed0" / "again"
    _write_sweeps(again, rng, 1, 32, None)
    write(again, static + robust_stage, "robust", epoch_seconds=90.0)
    assert partner_report.main([f"again={again}", "--out", str(tmp_path / "again_out")]) == 0
    rows = json.loads((tmp_path / "again_out" / "side_by_side.json").read_text())["rows"]
    assert {r["condition"]: r for r in rows}[partner_report.TRAINING_ROW]["again"][0] == 13.5

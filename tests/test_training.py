"""The training loop of train.py: logs, checkpoints, resume, divergence, bad input.

Most tests drive :func:`mjx_hands.training.run` with the pure-JAX point-reach task
(``env_factory``) so they compile in seconds; one runs ``train.py`` end to end on the
hand environment with a tiny budget.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import itertools
import json
import os
import signal
import subprocess
import sys
import types
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from compiles import counting_traces
from tiny import POINT_DDPG, point_config, point_factory

from mjx_hands import brax_agents, checkpoint, reward_params, run_directory, train_config, training
from mjx_hands.agents.ddpg import DDPGConfig
from mjx_hands.env_config import EnvConfig
from mjx_hands.point_reach import PointReach

ROOT = Path(__file__).resolve().parents[1]

def _learner(run_dir: Path) -> dict:
    meta = checkpoint.read_metadata(run_dir / "checkpoints")
    config = train_config.config_from_json(meta["config"])
    algo, _ = training.make_learner(config, env_factory=point_factory)
    state = algo.init(jax.random.PRNGKey(0))
    tree, _ = checkpoint.restore(
        run_dir / "checkpoints", algo.checkpoint_tree(state, config.save_replay)
    )
    return tree


TD3 = dataclasses.replace(  # every learner option at once
    POINT_DDPG,
    twin_critics=True,
    target_policy_noise=0.2,
    actor_update_interval=2,
    n_step=3,
    num_atoms=11,
    value_range=(-40.0, 5.0),
)


@pytest.mark.slow
@pytest.mark.parametrize("ddpg", [POINT_DDPG, TD3], ids=["ddpg", "td3_options"])
def test_resume_equals_an_uninterrupted_run(tmp_path, ddpg):
    full = training.run(
        point_config(tmp_path / "full", ddpg=ddpg), out=io.StringIO(), env_factory=point_factory
    )
    assert full["epochs"] == 4 and full["last_checkpoint"] == 4

    half = training.run(
        point_config(tmp_path / "split", epochs=2, ddpg=ddpg),
        out=io.StringIO(),
        env_factory=point_factory,
    )
    assert half["last_checkpoint"] == 2
    log = io.StringIO()
    resumed = training.run(
        point_config(tmp_path / "split", resume=True, ddpg=ddpg), out=log, env_factory=point_factory
    )
    assert "resumed from epoch 2" in log.getvalue()
    assert resumed["epochs"] == 4
    # The restored state must look to jit exactly like an epoch's output.
    assert full["epoch_compilations"] == resumed["epoch_compilations"] == 1

    a, b = _learner(tmp_path / "full"), _learner(tmp_path / "split")
    assert int(a["learner"].updates) == int(b["learner"].updates) > 0
    for x, y in zip(jax.tree.leaves(a["learner"]), jax.tree.leaves(b["learner"])):
        np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(a["buffer"].data.obs, b["buffer"].data.obs)

    # The best policy is chosen over the resumed run's whole history, as uninterrupted.
    assert resumed["best_checkpoint"] == full["best_checkpoint"]
    assert checkpoint.latest_step(tmp_path / "split" / "best") == full["best_checkpoint"]

    rows = (tmp_path / "split" / "metrics.csv").read_text().splitlines()
    assert len(rows) == 1 + 4  # header + one row per epoch, none repeated by the resume
    full_rows = (tmp_path / "full" / "metrics.csv").read_text().splitlines()
    header = full_rows[0].split(",")
    column = header.index("train/episode_return")
    assert [r.split(",")[column] for r in rows[1:]] == [r.split(",")[column] for r in full_rows[1:]]


def test_run_directory_holds_config_metrics_tensorboard_checkpoint_and_plot(tmp_path):
    run_dir = tmp_path / "run"
    training.run(
        point_config(run_dir, epochs=2, eval_every=1), out=io.StringIO(), env_factory=point_factory
    )
    config = json.loads((run_dir / "config.json").read_text())
    assert config["num_envs"] == 16 and config["ddpg"]["batch_size"] == 64
    expected = point_config(run_dir, epochs=2, eval_every=1)
    assert train_config.config_from_json(config) == train_config.resolved(expected)
    # Every reward knob is recorded as a number; runs from before read as the defaults
    # they trained with, and a named set (grids of 2026-12-02) as its numbers.
    recorded = train_config.config_from_json(config).env.knobs
    assert recorded == reward_params.task_knobs("handshake") and recorded.K_p == 4.0
    # Runs from before the environment was a field of its own hold its settings flat.
    flat = {k: v for k, v in config.items() if k != "env"} | config["env"]
    assert train_config.config_from_json(flat) == train_config.config_from_json(config)
    older = {k: v for k, v in flat.items() if k != "knobs"}
    defaults = reward_params.RewardWeights()
    assert train_config.config_from_json(older).env.knobs == reward_params.RewardKnobs(
        **{name: getattr(defaults, name) for name in reward_params.KNOB_NAMES}
    )
    named = flat | {"knobs": "authors", "task": "et"}
    assert train_config.config_from_json(named).env.knobs.K_p == 6.0
    with pytest.raises(TypeError, match="EnvConfig has no setting frobnicate"):
        train_config.config_from_json(config | {"env": config["env"] | {"frobnicate": 1}})
    with pytest.raises(ValueError, match="--knobs: K_alpha must be"):
        dataclasses.replace(
            train_config.TrainConfig(), env=EnvConfig(knobs=reward_params.RewardKnobs(K_alpha=-1.0))
        )
    rows = (run_dir / "metrics.csv").read_text().splitlines()
    assert "eval/success" in rows[0] and len(rows) == 3
    assert list((run_dir / "tensorboard").glob("events.out.tfevents.*"))
    assert checkpoint.latest_step(run_dir / "checkpoints") == 2
    png = (run_dir / "success.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"


def test_best_policy_is_kept_from_the_best_evaluation(tmp_path):
    run_dir = tmp_path / "run"
    summary = training.run(
        point_config(run_dir, epochs=6, eval_every=1), out=io.StringIO(), env_factory=point_factory
    )
    with open(run_dir / "metrics.csv") as f:
        rows = [{k: float(v) for k, v in r.items() if v} for r in csv.DictReader(f)]
    rank = ("eval/success", "eval/success_final", "eval/episode_return")
    best_row = max(rows, key=lambda r: tuple(r[k] for k in rank))  # first of equals wins
    epoch = int(best_row["epoch"])
    assert summary["best_checkpoint"] == epoch
    # One policy kept, the best one's, with its evaluation in the metadata.
    assert sorted(p.name for p in (run_dir / "best").iterdir() if p.name.isdigit()) == [str(epoch)]
    meta = checkpoint.read_metadata(run_dir / "best")
    assert meta["contents"] == "policy" and meta["eval"]["eval/success"] == best_row["eval/success"]
    algo, _ = training.make_learner(
        train_config.config_from_json(meta["config"]), env_factory=point_factory
    )
    like = algo.policy_tree(jax.eval_shape(algo.init, jax.random.PRNGKey(0)))
    tree, _ = checkpoint.restore(run_dir / "best", like)
    assert set(tree) == {"learner"}  # no env state, no replay buffer
    assert int(tree["learner"].updates) == best_row["train/updates"]
    for before, row in zip([{"train/updates": 0.0}, *rows], rows):  # the learner's own count
        done = row["train/updates"] - before["train/updates"]
        assert row["time/updates_per_second"] * row["time/epoch_seconds"] == pytest.approx(done)


def test_existing_run_is_not_overwritten_without_resume(tmp_path):
    run_dir = tmp_path / "run"
    training.run(
        point_config(run_dir, epochs=1, eval_every=1), out=io.StringIO(), env_factory=point_factory
    )
    with pytest.raises(FileExistsError, match="--resume"):
        training.run(point_config(run_dir, epochs=1), out=io.StringIO(), env_factory=point_factory)
    # Resuming with different networks is refused with the offending setting named.
    other = dataclasses.replace(POINT_DDPG, hidden_sizes=(16, 16))
    with pytest.raises(checkpoint.CheckpointError, match="ddpg.hidden_sizes"):
        training.run(
            point_config(run_dir, ddpg=other, resume=True), out=io.StringIO(), env_factory=point_factory
        )


@pytest.mark.slow
def test_checkpoint_of_another_shape_is_refused_naming_the_array(tmp_path):
    run_dir = tmp_path / "run"
    training.run(
        point_config(run_dir, epochs=1, eval_every=1), out=io.StringIO(), env_factory=point_factory
    )
    config = point_config(run_dir, ddpg=dataclasses.replace(POINT_DDPG, hidden_sizes=(16, 16)))
    algo, _ = training.make_learner(config, env_factory=point_factory)
    like = algo.checkpoint_tree(algo.init(jax.random.PRNGKey(0)), True)
    with pytest.raises(
        checkpoint.CheckpointError, match=r"actor_params.*float32\(32,\).*float32\(16,\)"
    ):
        checkpoint.restore(run_dir / "checkpoints", like)


class ExplodingReach(PointReach):
    """Rewards turn to NaN: the learner's losses diverge on the first update."""

    def step(self, state, action):
        state = super().step(state, action)
        return state.replace(reward=state.reward * jnp.nan)


@pytest.mark.slow
def test_divergence_stops_the_run_and_keeps_the_last_good_checkpoint(tmp_path):
    run_dir = tmp_path / "run"
    training.run(
        point_config(run_dir, epochs=2, eval_every=1), out=io.StringIO(), env_factory=point_factory
    )
    before = _learner(run_dir)

    def exploding(config, num_devices):
        return point_factory(config, num_devices, env_class=ExplodingReach)

    with pytest.raises(
        training.TrainingDiverged, match=r"epoch 3.*last good checkpoint \(epoch 2\)"
    ):
        training.run(
            point_config(run_dir, epochs=4, eval_every=1, resume=True),
            out=io.StringIO(),
            env_factory=exploding,
        )
    assert checkpoint.latest_step(run_dir / "checkpoints") == 2
    after = _learner(run_dir)
    for x, y in zip(jax.tree.leaves(before["learner"]), jax.tree.leaves(after["learner"])):
        np.testing.assert_array_equal(x, y)
        assert np.isfinite(x).all()


class _TerminateAt(io.StringIO):
    """Run output that sends this process SIGTERM once ``marker`` is printed."""

    def __init__(self, marker: str):
        super().__init__()
        self.marker = marker

    def write(self, text: str) -> int:
        n = super().write(text)
        if self.marker in text:
            os.kill(os.getpid(), signal.SIGTERM)
        return n


def test_sigterm_stops_the_run_like_ctrl_c_and_keeps_the_checkpoint(tmp_path):
    run_dir = tmp_path / "run"
    before = signal.getsignal(signal.SIGTERM)
    out = _TerminateAt("epoch    2/")
    result = training.run(
        point_config(run_dir, epochs=6, eval_every=1), out=out, env_factory=point_factory
    )
    assert result["stop_reason"] == "interrupted"
    assert "interrupted; the last checkpoint (epoch 1)" in out.getvalue()
    assert checkpoint.latest_step(run_dir / "checkpoints") == 1
    assert (run_dir / "success.png").is_file()
    assert signal.getsignal(signal.SIGTERM) is before  # the caller's handler is back


def exit_code(main, argv: list[str]) -> int:
    """A command's exit status in this process: its return value, or the code of the
    SystemExit its argument parser raises (tyro: 2 for bad choices)."""
    try:
        return main(argv)
    except SystemExit as stop:
        return stop.code


def _train_py(*args: str, timeout: float = 900) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(ROOT / "train.py"), *args],
        cwd=ROOT,
        capture_output=True,
        check=False,
        text=True,
        timeout=timeout,
    )


def test_train_py_help_lists_the_typed_options():
    result = _train_py("--help", timeout=120)
    assert result.returncode == 0, result.stderr
    for option in (
        "--task",
        "--reward",
        "--no-imitation",
        "--num-envs",
        "--resume",
        "--ddpg.batch-size",
        "--algo",
    ):
        assert option in result.stdout


@pytest.mark.parametrize(
    "args, message",
    [
        (["--task", "wave"], "wave"),
        (["--num-envs", "0"], "--num-envs must be positive"),
        (["--mocap", "/nonexistent/mocap", "--mocap-source", "optitrack"], "/nonexistent/mocap"),
        (["--algo", "sac", "--resume"], "--resume continues DDPG runs only"),
    ],
)
def test_train_py_bad_input_gets_a_message_not_a_traceback(args, message, tmp_path, capsys):
    from mjx_hands import train_cli

    assert exit_code(train_cli.main, [*args, "--run-dir", str(tmp_path / "r")]) == 2
    assert message in capsys.readouterr().err


@pytest.fixture(scope="session")  # once per session (or xdist worker), not per module visit
def hand_run(tmp_path_factory):
    """train.py on the hand environment with a tiny budget (compiles dominate: minutes)."""
    run_dir = tmp_path_factory.mktemp("hand") / "run"
    result = _train_py(
        "--task",
        "handshake",
        "--mocap-source",
        "synthetic",
        "--preset",
        "cpu",
        "--num-envs",
        "8",
        "--eval-envs",
        "8",
        "--epochs",
        "2",
        "--eval-every",
        "1",
        "--ddpg.unroll-length",
        "4",
        "--ddpg.iterations-per-epoch",
        "2",
        "--ddpg.updates-per-iteration",
        "2",
        "--ddpg.batch-size",
        "32",
        "--ddpg.min-replay-size",
        "32",
        "--ddpg.replay-capacity",
        "512",
        "--run-dir",
        str(run_dir),
    )
    return run_dir, result


def test_train_py_end_to_end_on_the_hand_task(hand_run):
    run_dir, result = hand_run
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-4000:]
    assert "epoch    2/2" in result.stdout and "eval success" in result.stdout
    config = json.loads((run_dir / "config.json").read_text())
    assert config["env"]["task"] == "handshake" and config["num_envs"] == 8
    rows = (run_dir / "metrics.csv").read_text().splitlines()
    assert len(rows) == 3 and "eval/success" in rows[0]
    assert checkpoint.latest_step(run_dir / "checkpoints") == 2
    assert (run_dir / "success.png").stat().st_size > 1000


def test_evaluate_reloads_the_policy_and_renders_a_video(hand_run):
    run_dir, result = hand_run
    assert result.returncode == 0
    evaluation = subprocess.run(
        [
            sys.executable,
            "-m",
            "mjx_hands.evaluate",
            str(run_dir),
            "--episodes",
            "8",
            "--video-episodes",
            "1",
            "--width",
            "160",
            "--height",
            "128",
        ],
        cwd=ROOT,
        capture_output=True,
        check=False,
        text=True,
        timeout=900,
        env=dict(os.environ, MUJOCO_GL="egl"),
    )
    assert evaluation.returncode == 0, evaluation.stdout[-2000:] + evaluation.stderr[-4000:]
    summary = json.loads((run_dir / "eval.json").read_text())
    assert summary["episodes"] == 8 and 0.0 <= summary["eval/success"] <= 1.0
    assert np.isfinite(summary["eval/episode_return"])
    video = (run_dir / "eval.mp4").read_bytes()
    assert video[4:8] == b"ftyp" and len(video) > 5000
    # The contact profile, from the sensor readings, agrees with the env's success flag.
    profile = summary["contact_profile"]
    assert profile["required"] == [f"{f}_middle" for f in ("th", "ff", "mf", "rf", "lf")]
    assert profile["success"] == summary["eval/success"]
    assert profile["success_final"] == summary["eval/success_final"]
    assert sum(profile["episodes_by_required_at_once"]) == 8
    assert len(profile["all_required_over_time"]) == 100
    assert (run_dir / "contact_profile.png").stat().st_size > 5000
    assert summary["checkpoint"] == {"kind": "latest", "epoch": 2}
    # One result schema: evaluate reports what training's evaluations logged.
    with open(run_dir / "metrics.csv") as f:
        logged = {k for k in csv.DictReader(f).fieldnames if k.startswith("eval/")}
    assert logged and logged <= set(summary)


def test_evaluate_loads_the_best_policy_without_compiling(hand_run):
    from mjx_hands import policies

    run_dir, result = hand_run
    assert result.returncode == 0
    with open(run_dir / "metrics.csv") as f:
        rows = [r for r in csv.DictReader(f)]
    best_policy = policies.load_policy(run_dir, best=True, eval_envs=8)
    best, epoch = best_policy.params, best_policy.epoch
    latest_policy = policies.load_policy(run_dir, eval_envs=8)
    latest = latest_policy.params
    assert int(best.updates) == float(rows[epoch - 1]["train/updates"])
    if epoch == 2:  # the best is the latest: the very same networks
        for x, y in zip(jax.tree.leaves(best), jax.tree.leaves(latest)):
            np.testing.assert_array_equal(x, y)
    else:
        assert int(best.updates) < int(latest.updates)
    # Policies of one program roll out through one compiled step: the parameters are
    # its arguments, not constants baked into a program per policy.
    from mjx_hands import rollouts

    # A policy whose actor outputs zeros must act as such through that same program.
    still = dataclasses.replace(
        latest, actor_params=jax.tree.map(jnp.zeros_like, latest.actor_params)
    )
    policies = [
        best_policy.act,
        latest_policy.act,
        jax.tree_util.Partial(latest_policy.act.func, still),
    ]
    keys = rollouts.episode_keys(0, 2)
    episodes = [rollouts.rollout(best_policy.single, policies[0], keys)]
    with counting_traces() as traced:
        episodes += [rollouts.rollout(best_policy.single, act, keys) for act in policies[1:]]
    assert traced == []
    assert not np.allclose(episodes[1]["qpos"][-1], episodes[2]["qpos"][-1])


def test_robustness_sweeps_a_trained_policy_over_orientations_and_speeds(hand_run, tmp_path):
    from mjx_hands import robustness

    run_dir, result = hand_run
    assert result.returncode == 0
    args = [str(run_dir), "--out", str(tmp_path), "--max-angle-deg", "30"]
    args += ["--angle-step-deg", "30", "--speeds", "0", "0.2", "--episodes", "2", "--chunk", "18"]
    assert robustness.main(args) == 0
    turned = json.loads((tmp_path / "robustness_orientation.json").read_text())
    moving = json.loads((tmp_path / "robustness_motion.json").read_text())
    assert turned["angles_deg"] == [-30.0, 0.0, 30.0] and turned["task"] == "handshake"
    grid = np.asarray(turned["success_final"])
    assert grid.shape == (3, 3) and np.all((grid >= 0) & (grid <= 1))
    assert np.asarray(moving["success"]).shape == (2,) and moving["speeds"] == [0.0, 0.2]
    # The untilted cell and the target at speed 0 run the very same episodes.
    for key in ("success", "success_final"):
        assert turned[key][1][1] == moving[key][0]
    for name in ("robustness_orientation.png", "robustness_motion.png"):
        assert (tmp_path / name).stat().st_size > 5000
    # Policies of one program share the sweeps' compiled programs (their parameters
    # are data): the same run loaded twice more traces nothing new.
    with counting_traces() as traced:
        assert robustness.main([str(run_dir), *args]) == 0
    assert traced == []
    # Imperfect sensing and actuation: noise 0 and delay 0 are the nominal episodes again.
    sensing = [str(run_dir), "--sweep", "sensing", "--out", str(tmp_path), "--episodes", "2"]
    assert robustness.main([*sensing, "--noise-mm", "0", "5", "--delays", "0", "1"]) == 0
    imperfect = json.loads((tmp_path / "robustness_sensing.json").read_text())
    assert imperfect["noise_mm"] == [0.0, 5.0] and imperfect["delays"] == [0, 1]
    for key in ("success", "success_final"):
        assert imperfect[f"noise_{key}"][0] == imperfect[f"delay_{key}"][0] == moving[key][0]
    assert (tmp_path / "robustness_sensing.png").stat().st_size > 5000
    assert robustness.main([*sensing, "--delays", "-1"]) == 2
    # The recorded partner beside the static target: the static condition is the nominal.
    partner = [str(run_dir), "--sweep", "partner", "--out", str(tmp_path), "--episodes", "2"]
    assert robustness.main([*partner, "--partner-shares", "0", "1"]) == 0
    replayed = json.loads((tmp_path / "robustness_partner.json").read_text())
    assert replayed["conditions"] == ["static", "recorded, share 0", "recorded, share 1"]
    for key in ("success", "success_final"):
        assert replayed[key][0] == moving[key][0] and len(replayed[key]) == 3
    assert (tmp_path / "robustness_partner.png").stat().st_size > 5000
    assert robustness.main([*partner, "--partner-shares", "1.5"]) == 2


def test_study_make_renders_blind_pairs_from_identical_starts(hand_run, tmp_path):
    import imageio.v2 as imageio

    from mjx_hands.study import layout, make

    run_dir, result = hand_run
    assert result.returncode == 0
    out = tmp_path / "study"
    args = ["--out", str(out), "--runs", str(run_dir), str(run_dir), "--pairs-per-task", "1"]
    args += ["--non-smooth-per-task", "1", "--width", "160", "--height", "128"]
    assert make.main(args) == 0
    study = layout.read_study(out)
    assert sorted(p.kind for p in study.pairs) == ["non_smooth", "regular"]
    assert {p.task for p in study.pairs} == {"handshake"}
    assert set(study.key) == {p.id for p in study.pairs}
    assert {e.left for e in study.key.values()} <= set(layout.POLICIES)
    for pair in study.pairs:
        first = [imageio.get_reader(out / v).get_data(0) for v in (pair.left, pair.right)]
        np.testing.assert_array_equal(first[0], first[1])  # the same start on both sides
        assert "imitation" not in pair.left + pair.right  # names give nothing away
    assert make.main(args) == 2  # the study exists: refused, nothing overwritten


def test_naturalness_measures_a_trained_policy(hand_run, tmp_path):
    from mjx_hands import naturalness

    run_dir, result = hand_run
    assert result.returncode == 0
    assert naturalness.main([str(run_dir), "--out", str(tmp_path), "--episodes", "3"]) == 0
    record = json.loads((tmp_path / "naturalness.json").read_text())
    (policy,) = record["policies"]
    assert policy["task"] == "handshake" and policy["epoch"] == 2
    # Hands start on a demonstration, 2 cm of noise: a 2-epoch policy (ddpg-ln, the default
    # learner) drifts, but within the arm's half-metre reach of it (0.32 m measured).
    assert 0.0 < policy["dtw"] < 0.5 and policy["jerk"] > 0 and policy["demo_jerk"] > 0
    assert 0.0 < policy["final_pose_error"] < 0.5
    assert "| handshake |" in (tmp_path / "naturalness.md").read_text()


@pytest.mark.parametrize(
    "args, message",
    [
        (["--episodes", "4", "--video-episodes", "5"], "--video-episodes 5"),
        (["--best", "--step", "3"], "--best and --step"),
        (["--best"], "no best policy"),
    ],
)
def test_evaluate_refuses_bad_choices_with_a_message(args, message, tmp_path, capsys):
    from mjx_hands import evaluate

    (tmp_path / "checkpoints").mkdir()
    assert evaluate.main([str(tmp_path), *args]) == 2
    assert message in capsys.readouterr().err


def test_evaluate_names_a_missing_run(capsys):
    from mjx_hands import evaluate

    assert evaluate.main(["/nonexistent/run"]) == 2
    assert "/nonexistent/run" in capsys.readouterr().err


@pytest.mark.parametrize("algo", ["ppo", "sac"])
@pytest.mark.slow
def test_brax_trainers_run_on_the_same_env_api(algo, tmp_path):
    run_dir = tmp_path / algo
    config = point_config(
        run_dir,
        algo=algo,
        epochs=4,
        eval_every=2,
        sac=brax_agents.SACConfig.like(
            dataclasses.replace(POINT_DDPG, min_replay_size=64, replay_capacity=2_000)
        ),
        ppo=brax_agents.PPOConfig.like(POINT_DDPG),
    )
    services = training.run_services(config, out=io.StringIO(), env_factory=point_factory)
    summary = brax_agents.run(config, services)
    assert 0.0 <= summary["final_eval"]["eval/success"] <= 1.0
    assert np.isfinite(summary["final_eval"]["eval/episode_return"])
    assert (run_dir / brax_agents.PARAMS_FILE).stat().st_size > 0
    rows = (run_dir / "metrics.csv").read_text().splitlines()
    assert len(rows) >= 3 and "eval/episode_reward" in rows[0]
    # Loaded back by its own learner (networks rebuilt, not Brax's inference function
    # from training): the same episodes give the training's final evaluation exactly.
    from mjx_hands import policies, rollouts

    loaded = policies.load_policy(run_dir, eval_envs=config.eval_envs, env_factory=point_factory)
    assert loaded.config.algo == algo and loaded.epoch == config.epochs
    keys = rollouts.episode_keys(config.seed + 1, config.eval_envs)
    trajectory = rollouts.rollout(loaded.single, loaded.act, keys)
    metrics, _ = rollouts.summarize(loaded.single, trajectory)
    assert metrics == pytest.approx(summary["final_eval"], rel=1e-6)
    with pytest.raises(ValueError, match="keeps only its final parameters"):
        policies.load_policy(run_dir, best=True, env_factory=point_factory)


def test_checkpoint_round_trips_empty_and_nested_arrays(tmp_path):
    """MJX data holds zero-size arrays; Orbax alone refuses them."""
    tree = {
        "a": np.arange(6, dtype=np.float32).reshape(2, 3),
        "empty": np.zeros((4, 0, 3), np.float32),
        "nested": (np.int32(7), np.zeros((0,), np.int32)),
    }
    checkpoint.save(tmp_path, 3, tree, {"epoch": 3})
    restored, meta = checkpoint.restore(tmp_path, tree)
    assert meta["epoch"] == 3
    for x, y in zip(jax.tree.leaves(tree), jax.tree.leaves(restored), strict=True):
        assert np.shape(x) == np.shape(y) and np.asarray(x).dtype == np.asarray(y).dtype
        np.testing.assert_array_equal(x, y)


def test_checkpoint_part_is_read_by_path_and_newer_steps_can_be_discarded(tmp_path):
    """evaluate reads only the learner (so an older environment-state layout still
    opens); a population drops steps some members saved beyond the others."""
    tree = {"learner": {"w": np.arange(6.0).reshape(2, 3)}, "env": {"x": np.ones(4)}}
    for step in (1, 2, 3):
        checkpoint.save(tmp_path, step, tree, {"epoch": step})
    part, meta = checkpoint.restore(tmp_path, {"learner": {"w": np.zeros((2, 3))}}, partial=True)
    np.testing.assert_array_equal(part["learner"]["w"], tree["learner"]["w"])
    assert meta["epoch"] == 3
    with pytest.raises(checkpoint.CheckpointError, match=r"lacks \['learner'\]\['v'\]"):
        checkpoint.restore(tmp_path, {"learner": {"v": np.zeros(2)}}, partial=True)
    with pytest.raises(checkpoint.CheckpointError, match="has 2 arrays but"):
        checkpoint.restore(tmp_path, {"learner": {"w": np.zeros((2, 3))}})
    assert checkpoint.discard_after(tmp_path, 1) == [2, 3]
    assert checkpoint.latest_step(tmp_path) == 1


def test_resume_from_the_command_line_starts_from_the_runs_own_config(tmp_path):
    from mjx_hands import train_cli

    run_dir = tmp_path / "run"
    config = point_config(run_dir, epochs=1, eval_every=1, seed=5)
    training.run(config, out=io.StringIO(), env_factory=point_factory)
    resumed = train_cli.default_config(["--run-dir", str(run_dir), "--resume", "--epochs", "3"])
    assert resumed == train_config.resolved(config)  # tyro applies --epochs on top
    fresh = train_cli.default_config(["--run-dir", str(tmp_path / "new"), "--preset", "cpu"])
    assert fresh == train_config.preset(
        "cpu", env=EnvConfig(profile="project"), algo="ddpg-ln"
    )  # recommended


def test_brax_wrapper_restarts_episodes_with_fresh_randomisation():
    """Brax's trainers get the project's auto-reset: fixed-length episodes, new goals."""
    from mjx_hands.brax_agents import wrap_for_brax

    env = wrap_for_brax(PointReach(episode_length=5), episode_length=5)
    state = env.reset(jax.random.split(jax.random.PRNGKey(0), 4))
    goals = [np.asarray(state.info["episode"].goal)]
    done_steps = []
    step = jax.jit(env.step)
    for t in range(1, 16):
        state = step(state, jnp.zeros((4, 2)))
        if np.all(np.asarray(state.done) == 1):
            done_steps.append(t)
            assert np.all(np.asarray(state.info["truncation"]) == 1)
            goals.append(np.asarray(state.info["episode"].goal))
        else:
            assert not np.any(np.asarray(state.done))
    assert done_steps == [5, 10, 15]
    np.testing.assert_array_equal(state.info["steps"], 5.0)
    np.testing.assert_array_equal(state.info["episode_metrics"]["length"], 5.0)
    assert all(not np.allclose(a, b) for a, b in itertools.pairwise(goals))
    with pytest.raises(ValueError, match="action_repeat"):
        wrap_for_brax(PointReach(), episode_length=20, action_repeat=2)


def test_invalid_ddpg_sizes_are_refused():
    with pytest.raises(ValueError, match="min_replay_size"):
        DDPGConfig(replay_capacity=1_000, min_replay_size=5_000)
    with pytest.raises(ValueError, match="updates_per_iteration"):
        DDPGConfig(updates_per_iteration=0)


@pytest.mark.slow
def test_resume_uses_the_checkpoints_own_replay_setting(tmp_path):
    run_dir = tmp_path / "run"
    training.run(
        point_config(run_dir, epochs=1, eval_every=1, save_replay=False),
        out=io.StringIO(),
        env_factory=point_factory,
    )
    log = io.StringIO()
    summary = training.run(
        point_config(run_dir, epochs=2, eval_every=1, save_replay=True, resume=True),
        out=log,
        env_factory=point_factory,
    )
    assert "resumed from epoch 1" in log.getvalue() and summary["epochs"] == 2
    assert "buffer" in [
        e["path"].split("'")[1] for e in checkpoint.read_metadata(run_dir / "checkpoints")["leaves"]
    ]


def test_metrics_log_survives_a_short_row(tmp_path):
    (tmp_path / "metrics.csv").write_text("epoch,train/env_steps,a\n1,10,0.5\n2,20\n")
    log = run_directory.MetricsLog(tmp_path)
    assert log.rows == [
        {"epoch": 1.0, "train/env_steps": 10.0, "a": 0.5},
        {"epoch": 2.0, "train/env_steps": 20.0},
    ]
    log.close()


def test_brax_trainers_refuse_a_run_directory_that_holds_a_run(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "metrics.csv").write_text("epoch\n1\n")
    with pytest.raises(FileExistsError, match="choose another --run-dir for --algo ppo"):
        config = point_config(run_dir, algo="ppo")
        brax_agents.run(config, training.run_services(config, io.StringIO(), point_factory))
    with pytest.raises(ValueError, match="--algo ppo has its own loop"):
        training.run(point_config(tmp_path / "other", algo="ppo"), out=io.StringIO())
    assert (run_dir / "metrics.csv").read_text() == "epoch\n1\n"


# ------------------------------------------------------------ faults: kill, damage, refuse
def _worker(run_dir: Path, epochs: int, *extra: str) -> subprocess.Popen:
    return subprocess.Popen(
        [
            sys.executable,
            str(ROOT / "tests" / "point_reach_worker.py"),
            str(run_dir),
            str(epochs),
            *extra,
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def _kill_at(proc: subprocess.Popen, marker: str) -> str:
    """SIGKILL ``proc`` (no handler runs, like a power cut) once it prints ``marker``."""
    seen = []
    for line in proc.stdout:
        seen.append(line)
        if marker in line:
            proc.kill()
            break
    proc.wait(timeout=60)
    assert marker in "".join(seen), "".join(seen)
    return "".join(seen)


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """The learner after 4 epochs of a run nothing happened to."""
    run_dir = tmp_path_factory.mktemp("uninterrupted") / "run"
    training.run(
        point_config(run_dir, epochs=4, eval_every=2), out=io.StringIO(), env_factory=point_factory
    )
    return _learner(run_dir)


def _truncate_newest_state(run_dir: Path) -> None:
    step_dir = run_dir / "checkpoints" / str(checkpoint.steps(run_dir / "checkpoints")[-1])
    file = max(
        (f for f in (step_dir / "state").rglob("*") if f.is_file()), key=lambda f: f.stat().st_size
    )
    file.write_bytes(file.read_bytes()[: file.stat().st_size // 2])


@pytest.mark.slow
@pytest.mark.parametrize(
    "fault",
    [
        "killed mid-epoch",
        "killed mid-save",
        "killed saving the best policy",
        "newest checkpoint damaged",
    ],
)
def test_a_run_hit_by_a_fault_resumes_to_the_uninterrupted_result(tmp_path, uninterrupted, fault):
    run_dir = tmp_path / "run"
    if fault == "killed mid-epoch":  # epoch 3's line prints before its checkpoint is saved
        _kill_at(_worker(run_dir, 4), "epoch    3/")
        possible_starts = {2, 3}
    elif fault == "killed mid-save":  # Orbax has written step 3, its digest not yet
        _kill_at(_worker(run_dir, 4, "--hold-before-digest", "checkpoints/3"), "holding")
        possible_starts = {2}
    elif fault == "killed saving the best policy":
        _kill_at(_worker(run_dir, 4, "--hold-before-digest", "best/2"), "holding")
        possible_starts = {2}
    else:
        training.run(
            point_config(run_dir, epochs=3, eval_every=2), out=io.StringIO(), env_factory=point_factory
        )
        _truncate_newest_state(run_dir)
        possible_starts = {2}
    left_behind = checkpoint.steps(run_dir / "checkpoints")
    log = io.StringIO()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        resumed = training.run(
            point_config(run_dir, epochs=4, eval_every=2, resume=True),
            out=log,
            env_factory=point_factory,
        )
    start = int(log.getvalue().split("resumed from epoch ")[1].split()[0])
    assert start in possible_starts and resumed["epochs"] == 4
    if start == 2 and 3 in left_behind:  # step 3 is not intact: skipped with a warning
        assert any("step 3:" in str(w.message) for w in caught), [str(w.message) for w in caught]
    after = _learner(run_dir)
    for x, y in zip(jax.tree.leaves(uninterrupted["learner"]), jax.tree.leaves(after["learner"])):
        np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(uninterrupted["buffer"].data.obs, after["buffer"].data.obs)
    rows = (run_dir / "metrics.csv").read_text().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == ["1.0", "2.0", "3.0", "4.0"]
    assert checkpoint.latest_step(run_dir / "best") in (2, 4)  # an intact best policy


@pytest.mark.slow
def test_checkpoints_by_epoch_and_by_wall_clock_besides_evaluations(tmp_path):
    every_2 = tmp_path / "every2"
    training.run(
        point_config(every_2, epochs=3, eval_every=5, checkpoint_every=2),
        out=io.StringIO(),
        env_factory=point_factory,
    )
    assert checkpoint.steps(every_2 / "checkpoints") == [2, 3]  # 3: the last epoch
    by_clock = tmp_path / "clock"
    training.run(
        point_config(by_clock, epochs=3, eval_every=5, checkpoint_every=100, checkpoint_minutes=1e-6),
        out=io.StringIO(),
        env_factory=point_factory,
    )
    assert checkpoint.steps(by_clock / "checkpoints") == [1, 2, 3]
    assert checkpoint.steps(by_clock / "best") == [3]  # the policy only at evaluations
    # Resuming on another device count names the counts, not array shapes.
    config = point_config(by_clock, epochs=3, resume=True)
    algo, _ = training.make_learner(config, env_factory=point_factory)
    with pytest.raises(
        checkpoint.CheckpointError, match=r"trained on 1 device\(s\), this run has 2"
    ):
        two_devices = types.SimpleNamespace(num_devices=2, checkpoint_tree=algo.checkpoint_tree)
        run_directory.RunDirectory(config).restore(
            two_devices, algo.init(jax.random.PRNGKey(0)), 0, 3
        )


@pytest.mark.slow
def test_divergence_before_the_first_checkpoint_says_there_is_none(tmp_path):
    def exploding(config, num_devices):
        return point_factory(config, num_devices, env_class=ExplodingReach)

    with pytest.raises(training.TrainingDiverged, match="no checkpoint was saved yet") as err:
        training.run(point_config(tmp_path / "run", epochs=2), out=io.StringIO(), env_factory=exploding)
    assert "checkpoints" not in str(err.value)


def _refused(argv: list[str], capsys) -> str:
    from mjx_hands import train_cli

    try:
        code = train_cli.main(argv)
    except SystemExit as exit_:  # tyro's own refusal of an option value
        code = exit_.code
    assert code == 2
    return capsys.readouterr().err


@pytest.mark.parametrize(
    "args, message",
    [
        (["--ddpg.hidden-sizes", "0"], "hidden_sizes=(0,)"),
        (["--target-rotation-noise", "nan"], "target_rotation_noise nan must be a finite number"),
        (["--ddpg.actor-learning-rate", "inf"], "actor_learning_rate=inf"),
        (["--max-minutes", "nan"], "--max-minutes must be a positive number"),
        (["--checkpoint-every", "0"], "--checkpoint-every must be positive"),
        (["--mocap", "/nonexistent/mocap"], "--mocap /nonexistent/mocap: no such folder"),
    ],
)
def test_bad_numbers_and_folders_are_refused_before_anything_is_written(
    args, message, tmp_path, capsys
):
    run_dir = tmp_path / "r"
    err = _refused([*args, "--run-dir", str(run_dir)], capsys)
    assert message in err
    assert not run_dir.exists()


def test_a_damaged_config_json_is_named_on_resume(tmp_path, capsys):
    run_dir = tmp_path / "r"
    run_dir.mkdir()
    (run_dir / "config.json").write_text('{"task": "handsh')
    err = _refused(["--run-dir", str(run_dir), "--resume"], capsys)
    assert f"{run_dir / 'config.json'} is unreadable" in err


def test_td3_names_the_projects_learner_with_its_options_and_ddpg_stays_the_papers(
    tmp_path, capsys
):
    import tyro

    from mjx_hands import experiments, train_cli

    td3_options = {
        "twin_critics": True,
        "target_policy_noise": 0.2,
        "target_noise_clip": 0.5,
        "actor_update_interval": 2,
        "n_step": 3,
        "layer_norm": True,
    }
    for kind in ("cpu", "gpu"):
        paper, td3 = train_config.preset(kind), train_config.preset(kind, algo="td3")
        options = ("twin_critics", "target_policy_noise", "actor_update_interval", "n_step")
        options += ("layer_norm", "num_atoms")
        assert [getattr(paper.ddpg, k) for k in options] == [False, 0.0, 1, 1, False, 1]
        assert td3 == dataclasses.replace(
            paper, algo="td3", ddpg=dataclasses.replace(paper.ddpg, **td3_options)
        )
        normed = train_config.preset(kind, algo="ddpg-ln")
        assert normed == dataclasses.replace(
            paper, algo="ddpg-ln", ddpg=dataclasses.replace(paper.ddpg, layer_norm=True)
        )
    argv = ["--preset", "cpu", "--algo", "td3", "--ddpg.n-step", "5"]
    parsed = tyro.cli(train_config.TrainConfig, default=train_cli.default_config(argv), args=argv)
    assert parsed.ddpg.n_step == 5 and parsed.ddpg.twin_critics  # a flag overrides one option
    grid = experiments.GridConfig(train=train_cli.preset_default(["--algo=td3", "--preset=cpu"]))
    assert grid.train == train_config.preset("cpu", algo="td3")
    refused = ["run", "--algo", "sac", "--preset", "cpu", "--run-dir", str(tmp_path / "g")]
    assert experiments.main(refused) == 2
    assert "--algo sac has its own loop" in capsys.readouterr().err


def test_replay_ratio_sets_the_updates_as_the_env_count_changes():
    cpu, gpu = train_config.preset("cpu"), train_config.preset("gpu")
    for config in (cpu, gpu):  # both presets replay 25.6 transitions per env step
        ratio = (
            config.ddpg.updates_per_iteration
            * config.ddpg.batch_size
            / (config.num_envs * config.ddpg.unroll_length)
        )
        assert ratio == pytest.approx(25.6)
    scaled = dataclasses.replace(cpu, num_envs=256, replay_ratio=25.6)
    assert scaled.ddpg.updates_per_iteration == 256  # 25.6 x 256 x 10 / 256
    delayed = dataclasses.replace(
        cpu,
        ddpg=dataclasses.replace(cpu.ddpg, actor_update_interval=3, updates_per_iteration=63),
        replay_ratio=1.0,
    )
    assert delayed.ddpg.updates_per_iteration == 3  # 2.5 rounds to one interval of 3
    with pytest.raises(ValueError, match="--replay-ratio"):
        dataclasses.replace(cpu, replay_ratio=-1.0)


@pytest.mark.parametrize(
    "error, code",
    [
        (training.TrainingDiverged("every run diverged"), 3),
        (ValueError("--epochs must be positive"), 2),
        (checkpoint.CheckpointError("no intact checkpoint"), 2),
        (FileExistsError("runs/x already holds a run"), 2),
    ],
)
def test_training_commands_report_refusals_and_divergence_as_exit_codes(error, code, capsys):
    from mjx_hands import train_cli

    def start():
        raise error

    assert train_cli.reported(start) == (None, code)
    assert capsys.readouterr().err == f"error: {error}\n"
    assert train_cli.reported(lambda: {"epochs": 1}) == ({"epochs": 1}, 0)


@pytest.mark.parametrize("passes", [SystemExit(0), KeyboardInterrupt(), RuntimeError("bug")])
def test_training_commands_let_help_interrupts_and_bugs_through(passes):
    """--help exits, Ctrl-C is handled by the loop, and a bug keeps its traceback."""
    from mjx_hands import train_cli

    def start():
        raise passes

    with pytest.raises(type(passes)):
        train_cli.reported(start)


def test_sac_and_ppo_have_their_own_settings_sized_like_the_preset():
    cpu = train_config.preset("cpu", algo="sac")
    assert cpu.sac == brax_agents.SACConfig.like(cpu.ddpg)
    assert cpu.sac.grad_updates_per_step == max(
        1, cpu.ddpg.updates_per_iteration // cpu.ddpg.unroll_length
    )
    assert cpu.ppo.env_steps_per_epoch == cpu.ddpg.unroll_length * cpu.ddpg.iterations_per_epoch
    # A run's config.json from before they existed reads back as it trained: DDPG's sizes.
    data = train_config.config_to_json(cpu)
    del data["sac"], data["ppo"]
    old = train_config.config_from_json(json.loads(json.dumps(data)))
    assert old.sac == cpu.sac and old.ppo == cpu.ppo
    # Their own settings survive config.json.
    mine = dataclasses.replace(cpu, sac=dataclasses.replace(cpu.sac, batch_size=77))
    back = train_config.config_from_json(json.loads(json.dumps(train_config.config_to_json(mine))))
    assert back.sac.batch_size == 77 and back == train_config.resolved(mine)


def test_an_exported_policy_plays_in_native_mujoco_without_jax(hand_run, tmp_path):
    """export: the ONNX policy's actions equal the JAX policy's (to 1e-5 on >= 1,000
    observations of its own episodes); the player, in a process without JAX, ends each
    exported episode as the training program did, and builds the very observations the
    environment does, step after step."""
    from mjx_hands import export, onnx_player, policies, rollouts

    run_dir, result = hand_run
    assert result.returncode == 0
    onnx_file = tmp_path / "out" / "policy.onnx"
    assert export.main([str(run_dir), "--onnx", str(onnx_file), "--episodes", "10"]) == 0
    record = json.loads((onnx_file.parent / "policy.json").read_text())
    assert record["check"]["observations"] >= 1000
    assert record["check"]["max_abs_action_difference"] <= 1e-5
    assert sum(p["size"] for p in record["observation"]) == 145
    assert [p["name"] for p in record["observation"]][:3] == ["qpos", "qvel_x_0.1", "contacts"]
    played = subprocess.run(
        [sys.executable, str(onnx_file.parent / "play.py"), str(onnx_file.parent),
         "--json", str(tmp_path / "play.json")],
        capture_output=True, check=False, text=True, timeout=600,
    )
    assert played.returncode == 0, played.stdout[-2000:] + played.stderr[-4000:]
    summary = json.loads((tmp_path / "play.json").read_text())
    assert not summary["jax_imported"] and summary["episodes"] == 10
    assert summary["same_outcome"] == 10 and summary["diverged"] == 0
    # The player's observations are the environment's (float32 rounding apart).
    loaded = policies.load_policy(run_dir, eval_envs=10)
    keys = rollouts.episode_keys(rollouts.EVAL_SEED, 10)
    trajectory = rollouts.rollout(loaded.single, loaded.act, keys, extra=lambda s: {"obs": s.obs})
    player = onnx_player.Player(onnx_file.parent)
    for i in (0, 7):
        np.testing.assert_allclose(
            player.play(i)["observations"], trajectory["obs"][:, i], atol=1e-5
        )
    # Bad requests are refused by name.
    assert export.main([str(run_dir), "--onnx", str(tmp_path / "p.txt")]) == 2
    assert export.main([str(tmp_path / "none"), "--onnx", str(onnx_file)]) == 2

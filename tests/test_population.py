"""Population training and experiment grids: a member trains as it would alone, members
are independent, a grid runs and resumes end to end, the report's statistics are right."""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import tiny

from mjx_hands import experiments, statistics, train_config, training
from mjx_hands.agents.ddpg import DDPG, DDPGConfig, member
from mjx_hands.point_reach import PointReach, make_point_reach

POINT = DDPGConfig(
    hidden_sizes=(32, 32),
    batch_size=64,
    replay_capacity=4_000,
    min_replay_size=256,
    unroll_length=4,
    updates_per_iteration=8,
    iterations_per_epoch=5,
)


def _train(algo: DDPG, seeds: list[int], epochs: int):
    state = algo.init(np.stack([np.asarray(jax.random.PRNGKey(s)) for s in seeds]))
    history = []
    for _ in range(epochs):
        state, metrics = algo.run_epoch(state)
        history.append(metrics)
    return jax.device_get(state), history


def _assert_trees_close(a, b, tol: float, what: str) -> None:
    """Leaves equal within ``tol`` relative and absolute (0: bit for bit)."""
    for (path, x), y in zip(jax.tree_util.tree_leaves_with_path(a), jax.tree.leaves(b)):
        np.testing.assert_allclose(
            np.asarray(x), np.asarray(y), atol=tol, rtol=tol,
            err_msg=f"{what}{jax.tree_util.keystr(path)}",
        )


def test_a_population_of_two_equals_two_runs_alone():
    """Point reach: members (seeds 0 and 5) of one population end where two single runs
    with those seeds end: parameters, optimiser states, replay buffers, metrics."""
    env = make_point_reach(16)
    pair = DDPG(env, POINT, episode_length=20, members=2)
    pop, pop_history = _train(pair, [0, 5], epochs=3)
    single = DDPG(env, POINT, episode_length=20)  # one learner, compiled once, two seeds
    for index, seed in enumerate([0, 5]):
        alone, history = _train(single, [seed], epochs=3)
        _assert_trees_close(member(pop, index).learner, member(alone, 0).learner, 1e-5, "learner")
        _assert_trees_close(member(pop, index).buffer, member(alone, 0).buffer, 1e-5, "buffer")
        assert pop_history[-1][index]["train/updates"] == history[-1][0]["train/updates"] > 0
        np.testing.assert_allclose(
            pop_history[-1][index]["train/episode_return"],
            history[-1][0]["train/episode_return"],
            rtol=1e-4,
        )
    # The members are distinct runs, not copies.
    a, b = (np.asarray(jax.tree.leaves(member(pop, i).learner.actor_params)[0]) for i in (0, 1))
    assert np.abs(a - b).max() > 1e-3


def test_population_refuses_member_info_of_the_wrong_size():
    with pytest.raises(ValueError, match="leading axis of the 3 members"):
        DDPG(make_point_reach(4), POINT, episode_length=20, members=3,
             member_info={"reward_weights": np.zeros((2, 5))})
    with pytest.raises(ValueError, match="one key per member"):
        DDPG(make_point_reach(4), POINT, episode_length=20, members=2).init(jax.random.PRNGKey(0))


@pytest.mark.slow
@tiny.HAND_GROUP
def test_reward_variants_are_data_and_members_are_independent():
    """On the hand task (native physics): a baseline-2 member of a population (its
    variant as data, beside full-reward members) trains as a baseline-2 run alone (variant
    from its config), so it neither sees its neighbours' reward nor disturbs them. The
    members are the grid's below (2 variants x 2 seeds), so it reuses this population."""
    grid = experiments.GridConfig(
        variants=("full", "baseline2"), seeds=2, train=tiny.hand_config(run_dir="unused")
    )
    members = [config for _, config in experiments.members(grid)]  # (full, b2) x seeds 0, 1

    def population(cs: list[train_config.TrainConfig]):
        algo, _ = training.make_learner(cs[0], population=cs)
        state, history = _train(algo, [c.seed for c in cs], epochs=2)
        evals = algo.evaluate(state, np.stack([np.asarray(jax.random.PRNGKey(9))] * len(cs)))
        return state, history, evals

    pair, history_pair, evals_pair = population(members)
    alone, history_alone, evals_alone = population(members[3:])
    assert (members[3].env.reward, members[3].seed) == ("baseline2", 1)
    # The neighbours were rewarded differently (baseline 2: no contact term).
    assert history_pair[-1][3]["env/reward/contact"] == 0.0
    assert history_pair[-1][1]["env/reward/contact"] >= 0.0
    assert history_pair[-1][1]["env/reward/total"] != history_pair[-1][3]["env/reward/total"]
    # Equivalence: the baseline-2 member (seed 1) equals the baseline-2 run alone.
    _assert_trees_close(member(pair, 3).learner, member(alone, 0).learner, 1e-4, "learner")
    for key in ("env/reward/position", "env/reward/total", "sgd/critic_loss"):
        np.testing.assert_allclose(history_pair[-1][3][key], history_alone[-1][0][key], rtol=1e-4)
    np.testing.assert_allclose(
        evals_pair[3]["eval/episode_return"], evals_alone[0]["eval/episode_return"], rtol=1e-4
    )
    assert evals_pair[3]["eval/final_fingertip_goal_distance"] > 0


# ------------------------------------------------------------------ grid CLI
@pytest.mark.slow
@tiny.HAND_GROUP
def test_a_grid_runs_resumes_and_reports_end_to_end(tmp_path, capfd):
    """The grid commands in this process (the resumed run reuses the first one's compiled
    programs); ``python -m mjx_hands.experiments`` itself is run by the refusal test below
    and by .ci/install_check."""
    from mjx_hands import evaluate

    grid = tmp_path / "grid"
    assert experiments.main(["run", *tiny.hand_cli_args(), "--variants", "full", "baseline2",
                             "--seeds", "2", "--epochs", "1", "--run-dir", str(grid)]) == 0
    first = capfd.readouterr().out
    assert "4 runs trained together" in first
    assert "eval success at the end: full" in first
    record = json.loads((grid / "grid.json").read_text())
    assert [(m["variant"], m["seed"]) for m in record["members"]] == [
        ("full", 0), ("full", 1), ("baseline2", 0), ("baseline2", 1)
    ]
    assert experiments.main(["run", "--run-dir", str(grid), "--resume", "--epochs", "2"]) == 0
    assert "resumed from epoch 1" in capfd.readouterr().out
    for m in record["members"]:
        run_dir = grid / m["run_dir"]
        config = json.loads((run_dir / "config.json").read_text())
        assert (config["seed"], config["env"]["reward"]) == (m["seed"], m["variant"])
        rows = list(csv.DictReader((run_dir / "metrics.csv").open()))
        assert [r["epoch"] for r in rows] == ["1.0", "2.0"]
        assert (run_dir / "best").is_dir() and (run_dir / "success.png").is_file()
    # A member is an ordinary run: evaluate opens it.
    member_dir = grid / "baseline2" / "seed1"
    assert evaluate.main([str(member_dir), "--episodes", "4", "--video-episodes", "0"]) == 0
    assert json.loads((member_dir / "eval.json").read_text())["episodes"] == 4
    assert experiments.main(["report", str(grid), "--out", str(tmp_path / "report")]) == 0
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())
    assert {(r["variant"], r["n_seeds"], r["final_epoch"]) for r in summary} == {
        ("full", 2, 2.0), ("baseline2", 2, 2.0)
    }
    assert (tmp_path / "report" / "fig4.png").stat().st_size > 10_000
    capfd.readouterr()
    assert experiments.main(["run", *tiny.hand_cli_args(), "--seeds", "1", "--run-dir", str(grid)]) == 2
    assert "already holds a grid" in capfd.readouterr().err


@pytest.mark.parametrize(
    "args, message",
    [
        (["run", "--seeds", "2"], "--run-dir is required"),
        (["run", "--run-dir", "x", "--reward", "baseline1"], "name --variants instead"),
        (["run", "--run-dir", "x", "--seeds", "0"], "--seeds must be positive"),
        (["run", "--run-dir", "x", "--variants", "full", "full"], "repeats a variant"),
        (["run", "--run-dir", "does/not/exist", "--resume"], "no grid to continue"),
        (["report", "does/not/exist"], "is not an experiment grid"),
        (["frobnicate"], "expected a command"),
    ],
)
def test_grid_commands_refuse_bad_input_with_a_message(args, message, capsys):
    assert experiments.main(args) == 2
    assert message in capsys.readouterr().err


# ------------------------------------------------------------------ report statistics
def _fixture_grid(root: Path, task: str, finals: dict[str, list[float]], distance: dict) -> Path:
    """A grid folder with hand-written metrics.csv files: two evaluations per member."""
    grid = root / task
    members = []
    for variant, values in finals.items():
        for seed, final in enumerate(values):
            run = grid / variant / f"seed{seed}"
            run.mkdir(parents=True)
            rows = [
                {"epoch": 5, "train/env_steps": 1000, "time/wall_seconds": 60,
                 "eval/success": 0.5, "eval/success_final": 0.1 * seed,
                 "eval/final_fingertip_goal_distance": 0.2},
                {"epoch": 10, "train/env_steps": 2000, "time/wall_seconds": 120,
                 "eval/success": 1.0, "eval/success_final": final,
                 "eval/final_fingertip_goal_distance": distance[variant][seed]},
            ]
            with (run / "metrics.csv").open("w", newline="") as f:
                writer = csv.DictWriter(f, fieldnames=list(rows[0]))
                writer.writeheader()
                writer.writerows(rows)
            members.append({"variant": variant, "seed": seed, "run_dir": f"{variant}/seed{seed}"})
    (grid / "grid.json").write_text(json.dumps({"task": task, "members": members}))
    return grid


def test_report_statistics_match_a_hand_computation(tmp_path):
    finals = {
        "full": [0.9, 0.8, 1.0],
        "baseline1": [0.2, 0.1, 0.3],
        "baseline2": [0.5, 0.7, 0.6],
        "no_imitation": [0.85, 0.95, 0.9],
    }
    distance = {
        "full": [0.01, 0.02, 0.03],
        "baseline1": [0.10, 0.12, 0.11],
        "baseline2": [0.05, 0.04, 0.06],
        "no_imitation": [0.02, 0.02, 0.03],
    }
    grid = _fixture_grid(tmp_path, "handshake", finals, distance)
    result = experiments.write_report([grid], tmp_path / "report")
    rows = {r["variant"]: r for r in result["summary"]}
    # Mean and standard error by hand: full = (0.9, 0.8, 1.0).
    assert rows["full"]["final_success_end"] == pytest.approx(0.9)
    assert rows["full"]["final_success_end_se"] == pytest.approx(0.1 / math.sqrt(3))
    assert rows["baseline1"]["best_success_end"] == pytest.approx(0.2)  # max(0.1*seed, final)
    # Welch's t for no_imitation vs baseline2 (statement 1 compares like with like):
    # means 0.9 / 0.6, sample variances 0.0025 / 0.01, n = 3.
    a, b = 0.0025 / 3, 0.01 / 3
    t_hand = (0.9 - 0.6) / math.sqrt(a + b)
    dof = (a + b) ** 2 / (a**2 / 2 + b**2 / 2)  # Welch-Satterthwaite
    first = result["statements"][0]
    test = next(t for t in first["tests"] if t["comparison"] == "no_imitation vs baseline2")
    assert test["t"] == pytest.approx(t_hand)
    from scipy import stats

    assert test["p"] == pytest.approx(2 * stats.t.sf(t_hand, dof))
    assert test["verdict"] == "held"
    # E.T. and the clap are missing: statements 1, 2 and 4 rest on the handshake only
    # and say so, statement 3 is untested.
    assert first["verdict"] == "held (partly tested)"
    assert result["statements"][1]["verdict"] == "held (partly tested)"  # b2 nearer than b1
    assert result["statements"][2]["verdict"] == "not tested"
    assert result["statements"][3]["verdict"] == "held (partly tested)"  # p > 0.05
    summary_csv = list(csv.DictReader((tmp_path / "report" / "summary.csv").open()))
    assert len(summary_csv) == 4 and "statements.md" in {p.name for p in (tmp_path / "report").iterdir()}


def test_holm_adjusts_by_hand_and_chunked_grids_report_as_one(tmp_path):
    # Holm by hand: sorted p 0.01, 0.02, 0.04 -> 3 x 0.01, max(0.03, 2 x 0.02), max(., 1 x 0.04).
    assert experiments.holm([0.04, 0.01, math.nan, 0.02]) == pytest.approx(
        [0.04, 0.03, math.nan, 0.04], nan_ok=True
    )
    finals = {"full": [0.9, 0.8, 1.0], "no_imitation": [0.85, 0.95, 0.9]}
    distance = {"full": [0.01, 0.02, 0.03], "no_imitation": [0.02, 0.02, 0.03]}
    whole = _fixture_grid(tmp_path / "whole", "et", finals, distance)
    # The same members in two chunks (seed 0; seeds 1-2), as a grid trained a seed at a time.
    first = _fixture_grid(tmp_path / "a", "et", {k: v[:1] for k, v in finals.items()}, distance)
    second = _fixture_grid(tmp_path / "b", "et", {k: v[1:] for k, v in finals.items()}, distance)
    record = json.loads((second / "grid.json").read_text())
    for m in record["members"]:  # the fixture numbers seeds from 0: this chunk is seeds 1-2
        m["seed"] += 1
    (second / "grid.json").write_text(json.dumps(record))
    one = experiments.write_report([whole], tmp_path / "r1")
    two = experiments.write_report([first, second], tmp_path / "r2")
    pick = lambda r: [(x["variant"], x["n_seeds"], x["final_success_end"]) for x in r["summary"]]
    assert pick(one) == pick(two) and [x["n_seeds"] for x in two["summary"]] == [3, 3]
    assert [s["verdict_holm"] for s in one["statements"]] == [
        s["verdict_holm"] for s in two["statements"]
    ]
    with pytest.raises(ValueError, match="seed 0 of et .* is in both"):
        experiments.write_report([whole, first], tmp_path / "r3")


def test_report_sets_the_paper_profile_beside_the_project_profile(tmp_path):
    finals = {"full": [0.5, 0.7, 0.6], "no_imitation": [0.4, 0.5, 0.6]}
    distance = {"full": [0.05] * 3, "no_imitation": [0.05] * 3}
    paper = _fixture_grid(tmp_path / "paper", "et", finals, distance)
    record = json.loads((paper / "grid.json").read_text())
    (paper / "grid.json").write_text(json.dumps(record | {"train": {"profile": "paper"}}))
    project = _fixture_grid(
        tmp_path / "project", "et", {"full": [0.9, 1.0, 0.95], "no_imitation": [0.9] * 3}, distance
    )
    result = experiments.write_report([paper, project], tmp_path / "report")
    assert {s["profile"] for s in result["statements"]} == {"paper", "project"}
    rows = {r["variant"]: r for r in result["profiles"]}
    # By hand: paper full 0.6 +- 0.1/sqrt(3), project full 0.95 +- 0.05/sqrt(3).
    assert rows["full"]["paper_final_success_end"] == pytest.approx(0.6)
    assert rows["full"]["project_final_success_end"] == pytest.approx(0.95)
    from scipy import stats

    expected = stats.ttest_ind([0.9, 1.0, 0.95], [0.5, 0.7, 0.6], equal_var=False).pvalue
    assert rows["full"]["p"] == pytest.approx(expected)
    table = (tmp_path / "report" / "profiles.md").read_text()
    assert "| et | full | 0.60 ± 0.06 (n=3, 2 k steps) | 0.95 ± 0.03 (n=3, 2 k steps) | +0.35 |" in table
    # fig4.md: one row per profile and task, the variants the grids hold, "-" for the rest
    # (0.1 / sqrt(3) = 0.058, 0.1 / sqrt(3) = 0.058 for paper; 0.05 / sqrt(3) = 0.029 for
    # the project's full, 0 for its constant no_imitation).
    fig4 = (tmp_path / "report" / "fig4.md").read_text().splitlines()
    assert fig4[0] == "| profile | task | env steps | full | no_imitation |"
    assert "| paper | et | 2 k | 0.60 ± 0.06 (3) | 0.50 ± 0.06 (3) |" in fig4
    assert "| project | et | 2 k | 0.95 ± 0.03 (3) | 0.90 ± 0.00 (3) |" in fig4
    # Only statement 4 is testable without baselines: one row per profile, its p-value.
    statement_rows = [line for line in fig4 if line.startswith("| paper | 4.")]
    p4 = stats.ttest_ind([0.5, 0.7, 0.6], [0.4, 0.5, 0.6], equal_var=False).pvalue
    assert len(statement_rows) == 1 and f"et full vs no_imitation: {p4:.2g}" in statement_rows[0]
    assert not any(line.startswith("| paper | 1.") for line in fig4)  # not tested: left out


def test_curves_average_seeds_at_shared_evaluations(tmp_path):
    grid = experiments.load_grid(
        _fixture_grid(tmp_path, "et", {"full": [1.0, 0.5]}, {"full": [0.0, 0.0]})
    )
    c = experiments.curves(grid)["full"]
    np.testing.assert_allclose(c["mean"], [0.05, 0.75])
    np.testing.assert_allclose(c["se"], [0.05, 0.25])
    np.testing.assert_allclose(c["env_steps"], [1000, 2000])


def test_seed_record_finds_the_target_and_the_worst_fall_by_hand():
    evals = [
        {"epoch": e, "train/env_steps": 1000 * e, "time/wall_seconds": 60 * e,
         "eval/success_final": v}
        for e, v in zip(range(1, 8), (0.1, 0.85, 0.95, 0.6, 0.9, 0.97, 0.92))
    ]  # fmt: skip
    record = experiments.seed_record(evals, 42.0)
    assert record["final"] == 0.92 and record["best"] == 0.97
    assert record["steps_to_target"] == 3000 and record["seconds_to_target"] == 180
    assert record["collapse"] == pytest.approx(0.35)  # best 0.95 so far, then 0.6
    assert record["first_epoch_seconds"] == 42.0
    never = experiments.seed_record(evals[:1], 1.0)
    assert math.isnan(never["steps_to_target"]) and never["collapse"] == 0.0


def test_compare_learners_from_grids(tmp_path, capsys):
    paper = _fixture_grid(tmp_path / "a", "handclap", {"full": [0.9, 0.8, 1.0]}, {"full": [0] * 3})
    other = _fixture_grid(tmp_path / "b", "handclap", {"full": [0.5, 0.7, 0.6]}, {"full": [0] * 3})
    argv = ["compare", f"ddpg={paper}", f"td3={other}", "--out", str(tmp_path / "cmp")]
    assert experiments.main(argv) == 0
    rows = json.loads((tmp_path / "cmp" / "learners.json").read_text())
    assert [r["label"] for r in rows] == ["ddpg", "td3"]
    assert rows[0]["final"] == pytest.approx(0.9) and rows[0]["seeds_at_target"] == 2
    assert rows[0]["seeds_reached_target"] == 2 and rows[0]["min_final"] == 0.8
    # Seeds 1 and 2 first evaluate 0.1 and 0.2 (< 0.8): no fall counted before 0.8.
    assert rows[0]["worst_collapse"] == 0.0
    # Welch's p of td3's finals against the baseline's (same spread, means 0.6 vs 0.9).
    assert rows[1]["p_final_vs_first"] == pytest.approx(statistics.welch([0.5, 0.7, 0.6], [0.9, 0.8, 1.0])[1])
    assert (tmp_path / "cmp" / "learners.png").stat().st_size > 5000
    assert "| td3 | 3 | 0.60 ± 0.06 |" in (tmp_path / "cmp" / "learners.md").read_text()
    assert experiments.main(["compare", str(paper)]) == 2
    assert "expected LABEL=GRID_DIR" in capsys.readouterr().err
    # At a 1,000-step budget each member's first evaluation is its last: 0.1 x seed.
    (early,) = experiments.compare_learners([("ddpg", paper)], "full", env_steps=1500)
    assert early["final_values"] == pytest.approx([0.0, 0.1, 0.2])
    assert early["final_env_steps"] == 1000 and early["final_epoch"] == 5
    argv = ["compare", f"ddpg={paper}", "--env-steps", "0", "--out", str(tmp_path / "x")]
    assert experiments.main(argv) == 2
    assert "--env-steps 0: expected a positive budget" in capsys.readouterr().err


def test_archive_keeps_what_compare_reads_and_leaves_checkpoints_out(tmp_path, capsys):
    grid = _fixture_grid(tmp_path / "runs", "handclap", {"full": [0.9, 0.6]}, {"full": [0] * 2})
    for seed in (0, 1):
        run = grid / "full" / f"seed{seed}"
        (run / "config.json").write_text(json.dumps({"seed": seed, "run_dir": str(run)}))
        (run / "checkpoints" / "10").mkdir(parents=True)
        (run / "checkpoints" / "10" / "state").write_bytes(b"x" * 1000)
    log = tmp_path / "grid.log"
    log.write_text("epoch 10/10\n")
    dest = tmp_path / "kept"
    assert experiments.main(["archive", str(grid), str(dest), "--log", str(log)]) == 0
    kept = sorted(str(f.relative_to(dest)) for f in dest.rglob("*") if f.is_file())
    assert kept == ["full/seed0/config.json", "full/seed0/metrics.csv", "full/seed1/config.json",
                    "full/seed1/metrics.csv", "grid.json", "grid.log"]  # fmt: skip
    config = json.loads((dest / "full" / "seed1" / "config.json").read_text())
    assert config == {"seed": 1, "run_dir": str(dest / "full" / "seed1")}
    original = experiments.compare_learners([("a", grid)], "full")
    archived = experiments.compare_learners([("a", dest)], "full")
    assert [{k: v for k, v in r.items() if k != "grids"} for r in archived] == [
        {k: v for k, v in r.items() if k != "grids"} for r in original
    ]
    # Refusals name what is wrong; nothing is overwritten.
    assert json.loads((dest / "grid.json").read_text())["archived_from"] == str(grid)
    assert experiments.main(["archive", str(grid), str(dest)]) == 2
    assert "not an empty folder" in capsys.readouterr().err
    assert experiments.main(["archive", str(grid), str(log)]) == 2  # a file, not a folder
    assert "not an empty folder" in capsys.readouterr().err
    assert experiments.main(["archive", str(tmp_path), str(tmp_path / "x")]) == 2
    assert "not an experiment grid" in capsys.readouterr().err
    (grid / "full" / "seed1" / "config.json").write_text("{not json")
    assert experiments.main(["archive", str(grid), str(tmp_path / "y")]) == 2
    assert "Expecting property name" in capsys.readouterr().err
    assert not (tmp_path / "y").exists()  # nothing written before every file was read
    (grid / "full" / "seed1" / "config.json").unlink()
    assert experiments.main(["archive", str(grid), str(tmp_path / "y")]) == 2
    assert "full/seed1/config.json" in capsys.readouterr().err
    record = json.loads((grid / "grid.json").read_text())
    record["members"][0]["run_dir"] = "../elsewhere"
    (grid / "grid.json").write_text(json.dumps(record))
    assert experiments.main(["archive", str(grid), str(tmp_path / "y")]) == 2
    assert "outside the grid: ../elsewhere" in capsys.readouterr().err
    assert not (tmp_path / "y").exists()


def test_committed_learner_grids_are_archives_compare_reads(tmp_path):
    """A committed grid record under benchmarks/learners reads as its grid did, and
    archiving it again changes no figure of its comparison."""
    committed = Path(experiments.__file__).parents[1] / "benchmarks" / "learners" / "et" / "layernorm"
    again = tmp_path / "again"
    experiments.archive_grid(committed, again)
    rows = experiments.compare_learners([("layernorm", committed)], "no_imitation")
    rows_again = experiments.compare_learners([("layernorm", again)], "no_imitation")
    assert rows[0]["n_seeds"] == 5
    assert {k: v for k, v in rows[0].items() if k != "grids"} == {
        k: v for k, v in rows_again[0].items() if k != "grids"
    }


def test_grid_members_differ_only_in_seed_and_variant():
    grid = experiments.GridConfig(variants=("full", "no_imitation"), seeds=2,
                     train=dataclasses.replace(train_config.preset("cpu"), run_dir="g", seed=3))
    pairs = experiments.members(grid)
    assert [(v, c.seed, c.env.reward, c.env.imitation, c.run_dir) for v, c in pairs] == [
        ("full", 3, "full", True, "g/full/seed3"),
        ("full", 4, "full", True, "g/full/seed4"),
        ("no_imitation", 3, "full", False, "g/no_imitation/seed3"),
        ("no_imitation", 4, "full", False, "g/no_imitation/seed4"),
    ]
    with pytest.raises(ValueError, match="differ only in"):
        training.run_population(
            [pairs[0][1], dataclasses.replace(pairs[1][1], num_envs=32)], env_factory=None
        )


class _RewardScaled(PointReach):
    """Point reach whose reward a member's variant scales: baseline1's scale is NaN, so
    that member diverges as soon as SGD starts while the other trains on."""

    def reset(self, rng):
        state = super().reset(rng)
        return state.replace(info=state.info | {"reward_weights": jnp.ones(())})

    def step(self, state, action):
        state = super().step(state, action)
        return state.replace(reward=state.reward * state.info["reward_weights"])

    def variant_for(self, weights):
        return jnp.asarray(np.nan if weights.position_points == "palm" else 1.0, jnp.float32)


def _scaled_factory(config, num_devices):
    from mjx_hands.env import BatchedEnv

    single = _RewardScaled()
    n, e = config.num_envs // num_devices, config.eval_envs // num_devices
    return BatchedEnv(single, n), BatchedEnv(single, e), single


def test_a_diverged_member_stops_alone(tmp_path, capsys):
    base = train_config.TrainConfig(num_envs=16, eval_envs=16, epochs=3, eval_every=1, ddpg=POINT)
    configs = [
        dataclasses.replace(base, run_dir=str(tmp_path / "ok")),
        dataclasses.replace(
            base,
            env=dataclasses.replace(base.env, reward="baseline1"),
            run_dir=str(tmp_path / "nan"),
        ),
    ]
    summaries = training.run_population(configs, out=io.StringIO(), env_factory=_scaled_factory)
    assert "the other members train on" in capsys.readouterr().err
    ok, nan = summaries
    assert ok["epochs"] == 3 and ok["last_checkpoint"] == 3
    assert nan["epochs"] < 3  # it logged nothing after diverging ...
    assert nan["last_checkpoint"] < 3  # ... and kept its last good checkpoint
    rows = list(csv.DictReader((tmp_path / "ok" / "metrics.csv").open()))
    assert all(math.isfinite(float(r["sgd/critic_loss"])) for r in rows)


def test_a_stop_waits_for_the_saves_of_an_epoch():
    import os
    import signal

    interrupts = training.Interrupts()
    interrupts.install()
    try:
        done = []
        with pytest.raises(KeyboardInterrupt), interrupts.deferred():
            os.kill(os.getpid(), signal.SIGTERM)  # arrives mid-"save" ...
            done.append("saved")  # ... which still completes
        assert done == ["saved"]
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGTERM)  # outside a save: at once
            for _ in range(1000):
                pass
    finally:
        interrupts.uninstall()


def test_a_population_resumes_from_the_epoch_all_members_saved(tmp_path):
    """A crash between two members' saves leaves one a checkpoint ahead; resume starts
    from the common epoch and discards the newer one (its epoch is trained again)."""
    from mjx_hands import checkpoint

    base = train_config.TrainConfig(num_envs=16, eval_envs=16, epochs=2, eval_every=1, ddpg=POINT)
    configs = [dataclasses.replace(base, seed=s, run_dir=str(tmp_path / f"s{s}")) for s in (0, 1)]
    training.run_population(configs, out=io.StringIO(), env_factory=_scaled_factory)
    for step in (2,):  # member 1 "did not finish" its epoch-2 save
        checkpoint.discard_after(tmp_path / "s1" / "checkpoints", step - 1)
    log = io.StringIO()
    resumed = [dataclasses.replace(c, resume=True, epochs=3) for c in configs]
    summaries = training.run_population(resumed, out=log, env_factory=_scaled_factory)
    assert "resumed from epoch 1" in log.getvalue()
    assert [s["last_checkpoint"] for s in summaries] == [3, 3]
    rows = list(csv.DictReader((tmp_path / "s0" / "metrics.csv").open()))
    assert [r["epoch"] for r in rows] == ["1.0", "2.0", "3.0"]

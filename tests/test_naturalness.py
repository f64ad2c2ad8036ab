"""Naturalness metrics against hand-computed values and an independent DTW."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from mjx_hands import naturalness, robustness


def reference_dtw(a: np.ndarray, b: np.ndarray) -> tuple[float, int]:
    """Textbook DTW on squared Euclidean costs: (minimal cost, length of its path)."""
    n, m = len(a), len(b)
    cost = np.full((n + 1, m + 1), np.inf)
    length = np.zeros((n + 1, m + 1), int)
    cost[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            d = float(np.sum((a[i - 1] - b[j - 1]) ** 2))
            moves = [(cost[i - 1, j - 1], i - 1, j - 1), (cost[i - 1, j], i - 1, j),
                     (cost[i, j - 1], i, j - 1)]  # fmt: skip
            best, pi, pj = min(moves)
            cost[i, j], length[i, j] = best + d, length[pi, pj] + 1
    return cost[n, m], length[n, m]


def test_dtw_rms_by_hand_and_against_a_textbook_dtw():
    # By hand: [0, 1, 2] against [0, 2]: the middle 1 pairs with either (cost 1), so the
    # path (0,0), (1,·), (2,1) has 3 pairs and squared cost 1.
    a, b = np.array([[0.0], [1.0], [2.0]]), np.array([[0.0], [2.0]])
    assert naturalness.dtw_rms(a, b) == pytest.approx(math.sqrt(1 / 3))
    assert naturalness.dtw_rms(a, a) == 0.0
    rng = np.random.default_rng(3)
    for n, m in ((12, 17), (20, 9)):
        x, y = rng.normal(size=(n, 18)), rng.normal(size=(m, 18))
        total, steps = reference_dtw(x, y)
        assert naturalness.dtw_rms(x, y) == pytest.approx(math.sqrt(total / steps), rel=1e-9)


def test_jerk_path_ratio_and_final_pose_by_hand():
    dt = 0.04
    t = np.arange(10) * dt
    cubic = np.stack([t**3, 0 * t, 0 * t], axis=1)  # x = t^3: jerk 6 m/s^3 everywhere
    assert naturalness.mean_jerk(cubic, dt) == pytest.approx(6.0, rel=1e-6)
    line = np.stack([2 * t, 0 * t, 0 * t], axis=1)  # constant velocity: no jerk
    assert naturalness.mean_jerk(line, dt) == pytest.approx(0.0, abs=1e-9)
    corner = np.array([[0, 0, 0], [3, 0, 0], [3, 4, 0]], float)
    assert naturalness.path_ratio(corner) == pytest.approx(7 / 5)
    assert math.isnan(naturalness.path_ratio(np.zeros((5, 3))))  # no direct path

    points = np.zeros((4, 6, 3))
    goals = np.zeros((6, 3))
    goals[:, 2] = 0.03  # every point 3 cm from its goal at the end
    demo = np.zeros((3, 6, 3))
    metrics = naturalness.episode_metrics(points, goals, demo, dt)
    assert metrics["final_pose_error"] == pytest.approx(0.03)
    assert metrics["dtw"] == 0.0
    # Per point: all six 1 cm off the demonstration everywhere -> 1 cm.
    shifted = demo.copy()
    shifted[..., 0] = 0.01
    assert naturalness.episode_metrics(points, goals, shifted, dt)["dtw"] == pytest.approx(0.01)


def test_demonstrations_are_resampled_at_the_control_rate():
    fps, dt = 100.0, 0.04
    frames = np.arange(21, dtype=float)  # x = frame index
    points = np.zeros((21, 6, 3))
    points[..., 0] = frames[:, None]
    out = naturalness.demo_at_control_rate(points, fps, dt)
    assert out.shape == (6, 6, 3)  # 0.00 .. 0.20 s every 0.04 s
    np.testing.assert_allclose(out[:, 0, 0], [0, 4, 8, 12, 16, 20])
    odd = naturalness.demo_at_control_rate(points, 120.0, dt)  # 4.8 frames per step
    np.testing.assert_allclose(odd[:, 0, 0], 4.8 * np.arange(odd.shape[0]))


def test_grids_expand_into_variants_and_the_ranking_follows_the_raters(tmp_path):
    grid = tmp_path / "grid"
    members = [
        {"variant": v, "seed": s, "run_dir": f"{v}/seed{s}"}
        for v in ("full", "no_imitation", "baseline1")
        for s in (0, 1)
    ]
    grid.mkdir()
    (grid / "grid.json").write_text(json.dumps({"task": "et", "variants": [], "members": members}))
    policies = naturalness.expand((str(grid),), ("full", "no_imitation"))
    assert [p["label"] for p in policies] == ["full"] * 2 + ["no_imitation"] * 2
    with pytest.raises(ValueError, match="no member of variants"):
        naturalness.expand((str(grid),), ("baseline2",))
    with pytest.raises(FileNotFoundError, match="no such run or grid folder"):
        naturalness.expand((str(tmp_path / "missing"),), ("full",))

    def policy(label, dtw):
        return {"task": "handclap", "label": label, "dtw": dtw, "jerk": 1.0,
                "path_ratio": 2.0, "final_pose_error": 0.1, "demo_jerk": 1.0,
                "demo_path_ratio": 1.5}  # fmt: skip

    per_policy = [policy("full", 0.05), policy("full", 0.06)]
    per_policy += [policy("no_imitation", 0.09), policy("no_imitation", 0.1)]
    rows = naturalness.table(per_policy)
    assert [(r["label"], r["n"]) for r in rows] == [("full", 2), ("no_imitation", 2)]
    assert rows[0]["dtw"] == pytest.approx(0.055) and rows[0]["dtw_se"] == pytest.approx(0.005)
    dtw = next(r for r in naturalness.rankings(rows, per_policy) if r["metric"] == "dtw")
    # Lower DTW with imitation, and the raters preferred imitation on the clap (+1.44).
    assert dtw["imitation_more_natural"] and dtw["agrees_with_raters"] and dtw["p"] < 0.05
    assert "| handclap | dtw |" in naturalness.markdown(
        rows, naturalness.rankings(rows, per_policy)
    )


@pytest.mark.parametrize("module", [naturalness, robustness])
def test_a_folder_without_a_policy_is_refused_with_a_message(module, tmp_path, capsys):
    args = [str(tmp_path)] + (["--out", str(tmp_path / "out")] if module is naturalness else [])
    assert module.main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and str(tmp_path) in err

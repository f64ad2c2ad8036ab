"""The contact profile against an explicit per-episode, per-step count."""

from __future__ import annotations

import numpy as np
import pytest

from mjx_hands import contact_profile
from mjx_hands import shadow_hand as sh


def _reference(contacts: np.ndarray, required: np.ndarray) -> dict:
    steps, episodes, sensors = contacts.shape
    req = [s for s in range(sensors) if required[s]]
    touched = [
        sum(any(contacts[t, e, s] for t in range(steps)) for e in range(episodes)) / episodes
        for s in range(sensors)
    ]
    best = [max(sum(contacts[t, e, s] for s in req) for t in range(steps)) for e in range(episodes)]
    over_time = [
        sum(all(contacts[t, e, s] for s in req) for e in range(episodes)) / episodes
        for t in range(steps)
    ]
    return {"touched": touched, "best": best, "over_time": over_time}


def test_summary_counts_what_touched_and_how_many_required_at_once():
    rng = np.random.default_rng(0)
    contacts = rng.random((30, 40, len(sh.CONTACT_SENSORS))) < 0.3
    required = np.zeros(len(sh.CONTACT_SENSORS), bool)
    required[[sh.sensor_index(s) for s in ("ff_middle", "mf_middle", "rf_middle")]] = True
    # One episode holds all three at step 7 only; another never touches anything.
    contacts[:, 0] = False
    contacts[7, 0, required] = True
    contacts[:, 1] = False
    got = contact_profile.summarize(contacts.astype(np.float32), required)
    want = _reference(contacts, required)
    np.testing.assert_allclose(list(got["touched"].values()), want["touched"])
    np.testing.assert_allclose(got["all_required_over_time"], want["over_time"])
    assert got["episodes_by_required_at_once"] == np.bincount(want["best"], minlength=4).tolist()
    assert got["success"] == pytest.approx(np.mean(np.array(want["best"]) == 3))
    assert got["required"] == ["ff_middle", "mf_middle", "rf_middle"]
    assert got["episodes_by_required_at_once"][0] >= 1  # episode 1
    np.testing.assert_allclose(
        list(got["in_contact"].values()), contacts.reshape(-1, contacts.shape[-1]).mean(0)
    )


def test_summary_rejects_readings_of_another_shape():
    with pytest.raises(ValueError, match=r"expected contacts \(T, n, 15\)"):
        contact_profile.summarize(np.zeros((5, 15)), np.ones(15, bool))


def test_plot_writes_a_png(tmp_path):
    contacts = np.random.default_rng(1).random((20, 8, len(sh.CONTACT_SENSORS))) < 0.5
    required = np.zeros(len(sh.CONTACT_SENSORS), bool)
    required[sh.sensor_index("ff_distal")] = True
    profile = contact_profile.summarize(contacts, required)
    path = tmp_path / "profile.png"
    contact_profile.plot(contacts, profile, path, "et", dt=0.04)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 5000


def test_clap_groups_count_fingers_not_sensors():
    """With the clap's groups a finger counts once whichever of its phalanges touches;
    success at the end is the last step's share, by explicit loops."""
    from mjx_hands import reward_params as rp

    groups = rp.success_group_mask("handclap")
    rng = np.random.default_rng(4)
    contacts = rng.random((12, 50, len(sh.CONTACT_SENSORS))) < 0.5
    profile = contact_profile.summarize(contacts, groups)
    rows = [g for g in groups if g.any()]

    def fingers(t, e):
        return sum(any(contacts[t, e, s] for s in np.flatnonzero(g)) for g in rows)

    best = [max(fingers(t, e) for t in range(12)) for e in range(50)]
    assert profile["episodes_by_required_at_once"] == np.bincount(best, minlength=5).tolist()
    assert profile["success_final"] == pytest.approx(np.mean([fingers(11, e) == 4 for e in range(50)]))
    assert profile["success"] == pytest.approx(np.mean([b == 4 for b in best]))
    assert profile["groups"][0] == ["ff_distal", "ff_middle"]

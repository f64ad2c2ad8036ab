"""benchmarks.contact_pairs: matching two contact lists per geom pair (no MJX compile)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from benchmarks import contact_pairs

CAPSULE, BOX = int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_BOX)
GEOM_TYPE = np.array([CAPSULE, CAPSULE, BOX, BOX])  # geoms 0, 1: capsules; 2, 3: boxes


def contacts(rows):
    """A contact list from rows of (geom1, geom2, dist, pos (3,), normal (3,), includemargin)."""
    return {
        "geom": np.array([r[0:2] for r in rows], int).reshape(-1, 2),
        "dist": np.array([r[2] for r in rows], float),
        "pos": np.array([r[3] for r in rows], float).reshape(-1, 3),
        "normal": np.array([r[4] for r in rows], float).reshape(-1, 3),
        "includemargin": np.array([r[5] for r in rows], float),
    }


Z = (0.0, 0.0, 1.0)


def test_match_pairs_points_by_nearest_position_and_geom_order():
    native = contacts(
        [
            (0, 1, 0.001, (0, 0, 0), Z, 0.002),  # capsule-capsule, MJX lists it swapped
            (0, 2, -0.001, (1, 0, 0), Z, 0.002),  # capsule-box: two points natively
            (0, 2, 0.0015, (1, 1, 0), Z, 0.002),
            (2, 3, 0.003, (5, 0, 0), Z, 0.002),  # box-box: in the gap, MJX misses it
        ]
    )
    mjx = contacts(
        [
            (1, 0, 0.0011, (0, 0.001, 0), (0.0, np.sin(0.01), -np.cos(0.01)), 0.002),
            (2, 0, -0.001, (1, 1.001, 0), Z, 0.002),  # matches the second native point
            (1, 3, -0.0005, (9, 0, 0), Z, 0.002),  # capsule-box, not listed natively
        ]
    )
    rows = {r["pair"]: r for r in contact_pairs.match(native, mjx)}
    assert rows[(0, 1)]["matched"] == [(0, 0)]
    assert rows[(0, 2)] == {"pair": (0, 2), "matched": [(2, 1)], "missed": [1], "extra": []}
    assert rows[(2, 3)]["missed"] == [3] and rows[(1, 3)]["extra"] == [2]

    pairs = contact_pairs.tally(GEOM_TYPE, [native], [mjx])
    assert set(pairs) == {"capsule-capsule", "capsule-box", "box-box"}
    cc, cb, bb = pairs["capsule-capsule"], pairs["capsule-box"], pairs["box-box"]
    assert (cc["native"], cc["found"], cc["extra"], cc["pairs_points_differ"]) == (1, 1, 0, 0)
    assert cc["dist"]["max"] == pytest.approx(1e-4)
    assert cc["pos"]["max"] == pytest.approx(1e-3)
    # normals compared from the lower geom id to the higher: MJX's swapped pair flips it
    assert cc["normal_deg"]["max"] == pytest.approx(np.degrees(0.01), rel=1e-6)
    assert (cb["native"], cb["found"], cb["missed"], cb["extra"]) == (2, 1, 1, 1)
    assert (cb["missed_active"], cb["missed_penetrating"]) == (1, 1)
    assert (cb["extra_active"], cb["extra_penetrating"]) == (1, 1)
    assert cb["pairs"] == 2 and cb["points_differ"] == {
        "native 2 / mjx 1": 1,
        "native 0 / mjx 1": 1,
    }
    assert cb["pos"]["max"] == pytest.approx(1e-3)
    assert (bb["native"], bb["found"], bb["missed_active"]) == (1, 0, 0)
    assert np.isnan(bb["dist"]["median"]) and bb["dist"]["n"] == 0

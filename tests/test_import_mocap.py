"""Motion-capture import: round trips through BVH and Motive CSV on the authors'
recordings (Algorithm 1's parameters must come back), resampling, and malformed input."""

from __future__ import annotations

import json
import tomllib

import jax
import numpy as np
import pytest
from conftest import real_data_or_skip

from mjx_hands import import_mocap, mocap, reward_params, tasks
from mjx_hands.mocap import mapping as mapping_lib
from mjx_hands.mocap import skeleton, takes
from mjx_hands.mocap.capture import to_demonstration


def _params(demo):
    return reward_params.algorithm1(demo, reward_params.task_weights(demo.task))


@pytest.mark.parametrize("fmt", ["bvh", "motive"])
def test_round_trip_keeps_algorithm1_on_the_authors_recordings(tmp_path, fmt):
    root = real_data_or_skip()
    for task in tasks.RELEASE_TASKS:
        demos = mocap.load_optitrack(task, root)
        mapping = mapping_lib.load_mapping(takes.export_demos(demos, tmp_path / task, fmt))
        back = takes.import_takes(takes.take_paths(tmp_path / task, fmt), mapping, task)
        assert len(back) == len(demos)
        for original, imported in zip(demos, back):
            assert (imported.contact_begin, imported.contact_end) == (
                original.contact_begin,
                original.contact_end,
            )
            want, got = _params(original), _params(imported)
            for path, a in jax.tree_util.tree_leaves_with_path(want):
                b = dict(jax.tree_util.tree_leaves_with_path(got))[path]
                np.testing.assert_allclose(b, a, atol=1e-5, err_msg=f"{task} {path}")


def test_command_line_import_writes_the_npz_and_a_report(tmp_path):
    demos = mocap.load_demonstrations("et", source="synthetic")[:2]
    mapping = takes.export_demos(demos, tmp_path / "takes", "bvh")
    out = tmp_path / "et.npz"
    argv = ["import", "--task", "et", "--mapping", str(mapping), "--out", str(out)]
    assert (
        import_mocap.main(argv + [str(p) for p in takes.take_paths(tmp_path / "takes", "bvh")]) == 0
    )
    back = mocap.load_synthetic("et", tmp_path)
    np.testing.assert_allclose(back[1].actor_points, demos[1].actor_points, atol=1e-6)
    report = json.loads(out.with_suffix(".report.json").read_text())
    assert report["actor"]["joints"]["FFJ2"].startswith("RightHandIndex1.x")
    assert [t["contact_window"] for t in report["takes"]] == [
        [d.contact_begin, d.contact_end] for d in demos
    ]
    assert import_mocap.main(argv[:-2] + ["--out", str(out), str(tmp_path / "none")]) == 1


def test_resampling_halves_the_rate_and_keeps_every_other_frame(tmp_path):
    demo = mocap.load_demonstrations("handshake", source="synthetic")[0]
    takes.export_demos([demo], tmp_path, "motive")
    mapping = mapping_lib.load_mapping(tmp_path / "mapping.toml")
    half = mapping_lib.Mapping(**{**vars(mapping), "fps": demo.fps / 2})
    (back,) = takes.import_takes(takes.take_paths(tmp_path, "motive"), half, "handshake")
    assert back.fps == demo.fps / 2 and back.num_frames == (demo.num_frames + 1) // 2
    np.testing.assert_allclose(back.actor_joints, demo.actor_joints[::2], atol=1e-6)
    np.testing.assert_allclose(back.actor_points, demo.actor_points[::2], atol=1e-6)
    assert back.contact_begin == -(-demo.contact_begin // 2)


def test_the_contact_rule_finds_the_closest_approach_without_windows(tmp_path):
    demo = mocap.load_demonstrations("handclap", source="synthetic")[0]
    takes.export_demos([demo], tmp_path, "bvh")
    mapping = mapping_lib.load_mapping(tmp_path / "mapping.toml")
    ruled = mapping_lib.Mapping(**{**vars(mapping), "windows": {}, "contact_margin": 0.005})
    (back,) = takes.import_takes(takes.take_paths(tmp_path, "bvh"), ruled, "handclap")
    distance = np.linalg.norm(demo.actor_points[:, 0], axis=-1)
    assert back.contact_begin == int(np.argmax(distance <= distance.min() + 0.005))
    assert back.contact_end == demo.num_frames - 1


# ------------------------------------------------------------------------ bad input
@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """One synthetic take in both formats, and the mappings that read them."""
    root = tmp_path_factory.mktemp("exported")
    demo = mocap.load_demonstrations("et", source="synthetic")[0]
    return {
        fmt: (root / fmt, takes.export_demos([demo], root / fmt, fmt)) for fmt in ("bvh", "motive")
    }


def _mapping_text(exported, fmt) -> str:
    return exported[fmt][1].read_text()


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda t: t.replace('format = "bvh"', 'format = "fbx"'), "format: expected one of"),
        (lambda t: t.replace('WRJ1 = "RightHand.y"\n', "", 1), r"missing \['WRJ1'\]"),
        (lambda t: t.replace('WRJ0 = "RightHand.x"', 'WRJ0 = "RightHand.w"', 1), "AXIS one of"),
        (lambda t: t.replace('WRJ0 = "RightHand.x"', 'WRJ9 = "RightHand.x"', 1), "unknown joints"),
        (lambda t: t.replace('length_unit = "cm"', 'length_unit = "inch"'), "length_unit"),
        (lambda t: t.replace('length_unit = "cm"\n', ""), "BVH files carry no unit"),
        (
            lambda t: t.replace("palm_axes = [[1.0, 0.0, 0.0]", "palm_axes = [[2.0, 0.0, 0.0]", 1),
            "rotation",
        ),
        (lambda t: "speed = 3\n" + t, "unknown keys"),
        (lambda t: t.replace("=", "", 1), "not a TOML mapping file"),
    ],
)
def test_malformed_mappings_are_named(tmp_path, exported, edit, message):
    file = tmp_path / "mapping.toml"
    file.write_text(edit(_mapping_text(exported, "bvh")))
    with pytest.raises(mocap.MocapError, match=message):
        mapping_lib.load_mapping(file)


def _copy_take(exported, fmt, tmp_path):
    import shutil

    folder, mapping = exported[fmt]
    (take,) = takes.take_paths(folder, fmt)
    dest = tmp_path / take.name
    (shutil.copytree if take.is_dir() else shutil.copy)(take, dest)
    return dest, mapping_lib.load_mapping(mapping)


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda t: t.replace("ROOT RightForearm", "RUT RightForearm"), "not a readable BVH"),
        (lambda t: t.replace("JOINT RightHand\n", "JOINT LeftHand\n"), "no joint 'RightHand'"),
        (lambda t: t[: len(t) // 2], "not a readable BVH"),
        (lambda t: t.replace("Frame Time:", "Frame Tim:"), "not a readable BVH"),
        (
            lambda t: t.replace(
                "CHANNELS 3 Xrotation Zrotation Yrotation", "CHANNELS 3 Xrotation Zrotation", 1
            ),
            "not a readable BVH",
        ),
    ],
)
def test_malformed_bvh_is_named(tmp_path, exported, edit, message):
    take, mapping = _copy_take(exported, "bvh", tmp_path)
    file = take / "actor.bvh"
    file.write_text(edit(file.read_text()))
    with pytest.raises(mocap.MocapError, match=message) as error:
        takes.read_take(take, mapping)
    assert "actor.bvh" in str(error.value)


def _edit_csv_cell(text: str, row: int, column: int, value: str) -> str:
    lines = text.splitlines()
    cells = lines[row].split(",")
    cells[column] = value
    lines[row] = ",".join(cells)
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda t: t.replace("Format Version,1.23", "Format Version,0.9"), "Format Version '0.9'"),
        (
            lambda t: t.replace("Rotation Type,Quaternion", "Rotation Type,XYZ"),
            "export with Rotation Type",
        ),
        (
            lambda t: t.replace("Coordinate Space,Global", "Coordinate Space,Local"),
            "Coordinate Space",
        ),
        (lambda t: _edit_csv_cell(t, 20, 5, ""), r"missing \(occluded\) from frame row 13"),
        (lambda t: _edit_csv_cell(t, 20, 5, "abc"), "not a number"),
        (lambda t: _edit_csv_cell(t, 20, 2, "3.0"), "not a unit quaternion"),
        (
            lambda t: t.replace("Actor:RightHand,", "Actor:LeftHand,"),
            "no rigid body or bone 'Actor:RightHand'",
        ),
        (lambda t: "\n".join(t.splitlines()[:5]), "not a Motive CSV take"),
        (lambda t: t.replace("Time (Seconds)", "Seconds"), "header of a Motive CSV export"),
    ],
)
def test_malformed_motive_csv_is_named(tmp_path, exported, edit, message):
    take, mapping = _copy_take(exported, "motive", tmp_path)
    take.write_text(edit(take.read_text()))
    with pytest.raises(mocap.MocapError, match=message) as error:
        takes.read_take(take, mapping)
    assert take.name in str(error.value)


@pytest.mark.parametrize("fmt", ["bvh", "motive"])
def test_random_damage_gives_a_mocap_error_or_a_valid_take(tmp_path, exported, fmt):
    """Fuzz: bytes replaced at random never escape as another exception type."""
    take, mapping = _copy_take(exported, fmt, tmp_path)
    file = take / "target.bvh" if fmt == "bvh" else take
    original = file.read_bytes()
    rng = np.random.default_rng(0)
    for _ in range(40):
        data = bytearray(original)
        for at in rng.integers(0, len(data), rng.integers(1, 8)):
            data[at] = int(rng.choice(list(b"0123456789.,-{} \nXYZabc\xff")))
        file.write_bytes(bytes(data))
        try:
            to_demonstration(takes.read_take(take, mapping), "et", mapping)
        except mocap.MocapError as error:
            assert str(error)
    file.write_bytes(original)


def test_the_exported_skeleton_mapping_parses_back_to_itself(exported):
    for fmt, (_, file) in exported.items():
        parsed = mapping_lib.load_mapping(file)
        again = mapping_lib.parse_mapping(tomllib.loads(mapping_lib.mapping_toml(parsed)))
        assert again.actor.joints == parsed.actor.joints == skeleton.mapping(fmt, {}).actor.joints
        assert again.windows == parsed.windows


def test_an_imported_task_is_its_takes_imported():
    # A task designed as takes (the fist bump) ships them and the npz import_mocap made
    # of them; both follow from its design.
    from mjx_hands import synthetic_demos

    for task in tasks.TASKS:
        spec = tasks.spec(task)
        if spec.synthetic_takes is None:
            continue
        folder = mocap.SYNTHETIC_PATH / task
        mapping = mapping_lib.load_mapping(folder / "mapping.toml")
        fresh = takes.import_takes(takes.take_paths(folder, mapping.format), mapping, task)
        stored = mocap.load_synthetic(task)
        designed = synthetic_demos.generate_task(task, len(stored))
        for a, b, c in zip(stored, fresh, designed):
            assert a.name == b.name
            for field in ("actor_joints", "target_joints", "actor_points", "actor_palm_rot"):
                np.testing.assert_allclose(getattr(a, field), getattr(b, field), atol=1e-6)
                np.testing.assert_allclose(getattr(a, field), getattr(c, field), atol=1e-5)
            assert (a.contact_begin, a.contact_end) == (c.contact_begin, c.contact_end)

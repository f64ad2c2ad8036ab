"""Checkpoint integrity: every step verifiable, a damaged newest step skipped for the
newest intact one with a warning naming what is wrong, a clear error when none is
intact. No JIT; each test writes a few small Orbax steps."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from mjx_hands import checkpoint


def _tree(value: float) -> dict:
    rng = np.random.default_rng(int(value))
    return {
        "learner": {"w": np.full((3, 4), value, np.float32)},
        "buffer": rng.normal(size=(2_000, 16)).astype(np.float32),  # incompressible, like replay
    }


def _save_steps(directory: Path, *steps: int) -> None:
    for step in steps:
        checkpoint.save(directory, step, _tree(step), {"epoch": step})


def _largest_state_file(step_dir: Path) -> Path:
    return max(
        (f for f in (step_dir / "state").rglob("*") if f.is_file()), key=lambda f: f.stat().st_size
    )


def _restored_value(directory: Path, step: int | None = None) -> float:
    tree, meta = checkpoint.restore(directory, _tree(0), step)
    assert meta["epoch"] == tree["learner"]["w"][0, 0]
    return float(tree["learner"]["w"][0, 0])


def _truncate(file: Path) -> None:
    data = file.read_bytes()
    file.write_bytes(data[: len(data) // 2])


def _flip_bytes(file: Path, count: int = 256) -> None:
    data = bytearray(file.read_bytes())
    middle = len(data) // 2
    data[middle : middle + count] = bytes(b ^ 0xFF for b in data[middle : middle + count])
    file.write_bytes(bytes(data))


def _empty_metadata(step_dir: Path) -> None:
    (step_dir / checkpoint.METADATA_FILE).write_text("")


def _delete_state(step_dir: Path) -> None:
    shutil.rmtree(step_dir / "state")


def _remove_digest(step_dir: Path) -> None:  # a save killed after Orbax, before the digest
    (step_dir / checkpoint.DIGEST_FILE).unlink()


DAMAGE = {
    "truncated state file": (lambda d: _truncate(_largest_state_file(d)), r"state/.* is damaged"),
    "256 flipped bytes": (lambda d: _flip_bytes(_largest_state_file(d)), r"state/.* is damaged"),
    "emptied metadata": (_empty_metadata, r"metadata/metadata is damaged"),
    "missing state item": (_delete_state, r"state/.* is missing"),
    "unfinished save": (_remove_digest, "unfinished"),
}


@pytest.mark.parametrize("name", DAMAGE)
def test_a_damaged_newest_checkpoint_falls_back_to_the_newest_intact_one(tmp_path, name):
    damage, message = DAMAGE[name]
    _save_steps(tmp_path, 1, 2, 3)
    damage(tmp_path / "3")
    assert checkpoint.damage(tmp_path, 2) is None
    assert checkpoint.steps(tmp_path) == [1, 2, 3]
    with pytest.warns(checkpoint.CheckpointWarning, match=f"step 3: .*{message}.*using step 2"):
        assert _restored_value(tmp_path) == 2.0
    with pytest.warns(checkpoint.CheckpointWarning):
        assert checkpoint.read_metadata(tmp_path)["epoch"] == 2
    # Asked for by number, it is refused with the same reason (never Orbax's own message).
    with pytest.raises(checkpoint.CheckpointError, match=f"step 3 cannot be used: .*{message}"):
        checkpoint.restore(tmp_path, _tree(0), step=3)


def test_no_intact_checkpoint_is_a_clear_error_listing_each_step(tmp_path):
    _save_steps(tmp_path, 1, 2)
    _truncate(_largest_state_file(tmp_path / "2"))
    _empty_metadata(tmp_path / "1")
    with pytest.raises(
        checkpoint.CheckpointError,
        match=r"no intact checkpoint in .*step 2: .*state/.*damaged.*step 1: .*metadata",
    ):
        checkpoint.restore(tmp_path, _tree(0))


def test_every_saved_file_is_covered_by_the_digest(tmp_path):
    _save_steps(tmp_path, 1)
    step_dir = tmp_path / "1"
    digest = json.loads((step_dir / checkpoint.DIGEST_FILE).read_text())["sha256"]
    files = {
        f.relative_to(step_dir).as_posix()
        for f in step_dir.rglob("*")
        if f.is_file() and f.name != checkpoint.DIGEST_FILE
    }
    assert set(digest) == files and any(name.startswith("state/") for name in files)


def test_a_checkpoint_written_before_digests_still_opens(tmp_path):
    _save_steps(tmp_path, 1)
    step_dir = tmp_path / "1"
    _remove_digest(step_dir)
    # An older version's record: no "format" key.
    record_file = step_dir / checkpoint.METADATA_FILE
    record = json.loads(record_file.read_text())
    del record["format"]
    record_file.write_text(json.dumps(record))
    assert checkpoint.damage(tmp_path, 1) is None
    assert _restored_value(tmp_path) == 1.0


def test_discarding_newer_steps_keeps_damaged_ones_aside(tmp_path):
    _save_steps(tmp_path, 1, 2, 3)
    _truncate(_largest_state_file(tmp_path / "3"))
    assert checkpoint.discard_after(tmp_path, 1) == [2, 3]
    assert checkpoint.steps(tmp_path) == [1]
    aside = list((tmp_path.parent / f"{tmp_path.name}.damaged").iterdir())
    assert [p.name.split("-")[0] for p in aside] == ["3"]
    # The directory takes step 2 again after the discard.
    _save_steps(tmp_path, 2)
    assert _restored_value(tmp_path) == 2.0

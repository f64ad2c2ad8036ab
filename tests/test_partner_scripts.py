"""benchmarks/partners/seeds.sh, the script that trains, sweeps and archives the partner
records: run in a scratch checkout with a stand-in for Python that writes what train.py,
the robustness sweeps and the naturalness metrics would (no training), so that what it
archives, skips, retrains and refuses is checked in seconds."""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

STAND_IN = f"""#!{sys.executable}
# Stands in for Python: train.py writes (or resumes) a run folder whose evaluations are a
# function of seed and epoch; -m mjx_hands.robustness / naturalness write their records;
# anything else (the script's own checks) runs the real interpreter.
import csv, json, os, sys
args = sys.argv[1:]
def value(flag, default=None):  # the last one given wins, as on train.py's command line
    return args[len(args) - args[::-1].index(flag)] if flag in args else default
if args[:1] == ["train.py"]:
    run = value("--run-dir")
    os.makedirs(run, exist_ok=True)
    rows, seed = [], 0
    if "--resume" in args:
        seed = json.load(open(os.path.join(run, "config.json")))["seed"]
        rows = list(csv.reader(open(os.path.join(run, "metrics.csv"))))[1:]
    else:
        seed = int(value("--seed"))
    if os.environ.get("FAKE_SEED_SHIFT"):  # a retrained run that does not reproduce
        seed += 1
    json.dump({{"seed": seed, "run_dir": os.path.abspath(run), "partners": value("--partners", "static")}},
              open(os.path.join(run, "config.json"), "w"))
    for epoch in range(len(rows) + 1, int(value("--epochs")) + 1):
        rows.append([f"{{epoch:.1f}}", f"{{(seed * 7 + epoch) % 10 / 10:.2f}}", "12.5"])
    with open(os.path.join(run, "metrics.csv"), "w", newline="") as f:
        csv.writer(f).writerows([["epoch", "eval/success", "time/wall_seconds"]] + rows)
    print("trained", run)
elif args[:2] == ["-m", "mjx_hands.robustness"]:
    if os.environ.get("FAKE_FAIL") == "robustness":
        sys.exit("robustness failed")
    out = value("--out")
    os.makedirs(out, exist_ok=True)
    json.dump({{"run": os.path.abspath(args[2])}}, open(os.path.join(out, "robustness_motion.json"), "w"))
    open(os.path.join(out, "robustness_motion.png"), "wb").write(b"png")
elif args[:2] == ["-m", "mjx_hands.naturalness"]:
    out = value("--out")
    json.dump({{"jerk": 1.0}}, open(os.path.join(out, "naturalness.json"), "w"))
else:
    os.execv({sys.executable!r}, [{sys.executable!r}] + args)
"""


@pytest.fixture()
def checkout(tmp_path):
    """A scratch git checkout holding the partner scripts, and a stand-in Python."""
    repo = tmp_path / "repo"
    (repo / "benchmarks" / "partners").mkdir(parents=True)
    for name in ("seeds.sh", "archive.sh"):
        shutil.copy(REPO / "benchmarks" / "partners" / name, repo / "benchmarks" / "partners")
    git = lambda *a: subprocess.run(["git", *a], cwd=repo, check=True, capture_output=True)
    git("init", "-q")
    git("add", ".")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "scripts")
    python = tmp_path / "python"
    python.write_text(STAND_IN)
    python.chmod(0o755)
    return repo, python, repo / "runs" / "partners"  # as the default: inside the checkout


def seeds(checkout, *args, **env):
    repo, python, runs = checkout
    environ = os.environ | {"PYTHON": str(python), "RUNS": str(runs)} | env
    return subprocess.run(["bash", "benchmarks/partners/seeds.sh", *args], cwd=repo,
                          env=environ, capture_output=True, text=True, check=False)  # fmt: skip


def status(checkout) -> str:
    return (checkout[2] / "status").read_text()


def last_epoch(folder: Path) -> float:
    return float(list(csv.DictReader(open(folder / "metrics.csv")))[-1]["epoch"])


RECORD = {"config.json", "metrics.csv", "robustness_motion.json", "robustness_motion.png",
          "naturalness.json", "train.log"}  # fmt: skip


def test_a_seed_is_archived_whole_with_relative_paths_and_then_skipped(checkout):
    repo, _, _ = checkout
    assert seeds(checkout, "et", "0").returncode == 0
    seed = repo / "benchmarks" / "partners" / "et" / "seed0"
    assert {p.name for p in seed.iterdir()} == {"static", "static_then_robust"}
    for setup, epochs in (("static", 60), ("static_then_robust", 100)):
        assert {p.name for p in (seed / setup).iterdir()} == RECORD
        assert last_epoch(seed / setup) == epochs
        for name in ("config.json", "robustness_motion.json"):
            text = (seed / setup / name).read_text()
            assert f"{repo}/" not in text  # the checkout's paths made relative
            assert f'"runs/partners/et-s0-{setup}"' in text
    assert json.loads((seed / "static_then_robust" / "config.json").read_text())["partners"] == "robust"
    assert "seed 0 done" in status(checkout)
    assert seeds(checkout, "et", "0").returncode == 0
    assert "exists, skipped" in status(checkout)


def test_a_new_stage_of_an_archived_seed_retrains_its_static_run_only_if_it_reproduces(checkout):
    repo, _, runs = checkout
    assert seeds(checkout, "et", "1").returncode == 0
    seed = repo / "benchmarks" / "partners" / "et" / "seed1"
    shutil.rmtree(runs / "et-s1-static")  # a fresh machine: the static run is gone
    stage = {"PARTNERS": "mixed", "STAGE_FLAGS": "--epochs 240", "STAGE_LABEL": "long"}
    refused = seeds(checkout, "et", "1", FAKE_SEED_SHIFT="1", **stage)
    assert refused.returncode == 0
    assert not (seed / "static_then_mixed_long").exists()
    assert "static_then_mixed_long stage of seed 1 (static run retrained) failed" in status(checkout)
    shutil.rmtree(runs / "et-s1-static")
    assert seeds(checkout, "et", "1", **stage).returncode == 0
    assert {p.name for p in seed.iterdir()} == {"static", "static_then_robust", "static_then_mixed_long"}
    assert {p.name for p in (seed / "static_then_mixed_long").iterdir()} == RECORD
    assert last_epoch(seed / "static_then_mixed_long") == 240
    assert "static_then_mixed_long stage of seed 1 done" in status(checkout)


def test_a_seed_that_fails_leaves_nothing_archived_and_says_so(checkout):
    repo, _, _ = checkout
    assert seeds(checkout, "et", "2", FAKE_FAIL="robustness").returncode == 0
    partners = repo / "benchmarks" / "partners"
    assert not (partners / "et" / "seed2").exists()
    assert not list(partners.glob("et/*.tmp"))
    assert "seed 2 failed" in status(checkout)


def test_seeds_needs_a_task_and_a_seed(checkout):
    missing = seeds(checkout, "et")
    assert missing.returncode == 2 and "no seed given" in missing.stderr
    bad = seeds(checkout, "et", "0", PARTNERS="sometimes")
    assert bad.returncode == 2 and "expected robust or mixed" in bad.stderr

"""The rating study: folder layout, answer store, statistics, report, server, browser."""

from __future__ import annotations

import csv
import http.client
import importlib.util
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
import urllib.parse
from pathlib import Path

import numpy as np
import pytest

from mjx_hands.study import layout, report, server, store

ROOT = Path(__file__).resolve().parents[1]

# (id, task, kind, policy on the left) of the fixture study.
PAIRS = [
    ("p01", "handshake", "regular", "imitation"),
    ("p02", "handshake", "non_smooth", "no_imitation"),
    ("p03", "handclap", "regular", "imitation"),
    ("p04", "et", "regular", "no_imitation"),
    ("p05", "et", "non_smooth", "imitation"),
]


# ------------------------------------------------------------------ fixtures
@pytest.fixture(scope="session")
def tiny_videos(tmp_path_factory) -> list[Path]:
    """Two real H.264 mp4 files: 16 frames of 64x64 in one solid colour each."""
    import imageio.v2 as imageio

    folder = tmp_path_factory.mktemp("videos")
    paths = []
    for name, colour in (("red", (200, 40, 40)), ("blue", (40, 60, 200))):
        path = folder / f"{name}.mp4"
        frames = np.broadcast_to(np.asarray(colour, np.uint8), (16, 64, 64, 3))
        imageio.mimwrite(path, list(frames), fps=8, codec="libx264", macro_block_size=16)
        paths.append(path)
    return paths


def make_study(study_dir: Path, videos: list[Path]) -> layout.Study:
    """The fixture study in ``study_dir``: PAIRS with copies of the tiny videos."""
    (study_dir / layout.VIDEOS_DIR).mkdir(parents=True)
    pairs, key = [], {}
    for i, (pid, task, kind, left) in enumerate(PAIRS):
        for side, video in (("left", videos[i % 2]), ("right", videos[(i + 1) % 2])):
            shutil.copy(video, study_dir / layout.video_path(pid, side))
        pairs.append(
            {
                "id": pid,
                "task": task,
                "kind": kind,
                "left": layout.video_path(pid, "left"),
                "right": layout.video_path(pid, "right"),
            }
        )
        key[pid] = {"left": left, "seed": 100 + i, "start": i}
    return layout.write_study(study_dir, "Naturalness test", pairs, key)


@pytest.fixture
def study(tmp_path, tiny_videos) -> layout.Study:
    return make_study(tmp_path / "study", tiny_videos)


def edit_json(path: Path, edit) -> None:
    content = json.loads(path.read_text())
    edit(content)
    path.write_text(json.dumps(content))


# -------------------------------------------------------------------- layout
def test_answer_value_maps_the_scale_to_the_preference_for_imitation():
    assert [layout.answer_value(i, "imitation") for i in range(5)] == [2, 1, 0, -1, -2]
    assert [layout.answer_value(i, "no_imitation") for i in range(5)] == [-2, -1, 0, 1, 2]
    for bad in (-1, 5, True, 2.0, "2"):
        with pytest.raises(ValueError, match="answer must be an integer 0..4"):
            layout.answer_value(bad, "imitation")
    with pytest.raises(ValueError, match="left must be one of"):
        layout.answer_value(0, "baseline")


def test_write_study_round_trips_and_keeps_the_key_out_of_study_json(study):
    again = layout.read_study(study.dir)
    assert again == study
    assert [p.id for p in study.pairs] == [p[0] for p in PAIRS]
    assert study.key["p02"].left == "no_imitation" and study.key["p02"].seed == 101
    assert study.key["p02"].extra == {"start": 1}
    public = json.loads((study.dir / layout.STUDY_FILE).read_text())
    assert public["format"] == 1 and public["scale"] == list(layout.SCALE)
    assert public["pairs"][0] == {
        "id": "p01",
        "task": "handshake",
        "kind": "regular",
        "left": "videos/p01_L.mp4",
        "right": "videos/p01_R.mp4",
    }
    assert "imitation" not in json.dumps(public) and "seed" not in json.dumps(public)
    assert layout.pair_id(0) == "p01" and layout.pair_id(10) == "p11"


def test_write_study_refuses_a_study_that_already_has_answers(study):
    store.AnswerStore(study.answers_path).submit("r", "p01", 2)
    pairs = [p.public() for p in study.pairs]
    key = dict(study.key)
    with pytest.raises(FileExistsError, match="answers.sqlite exists"):
        layout.write_study(study.dir, "again", pairs, key)


def test_write_study_validates_before_writing(tmp_path):
    (tmp_path / "videos").mkdir()
    pair = {
        "id": "p01",
        "task": "et",
        "kind": "regular",
        "left": "videos/a.mp4",
        "right": "videos/b.mp4",
    }
    with pytest.raises(FileNotFoundError, match="video of pair p01 .left. is missing"):
        layout.write_study(tmp_path, "s", [pair], {"p01": {"left": "imitation", "seed": 0}})
    assert not (tmp_path / layout.STUDY_FILE).exists() and not (tmp_path / layout.KEY_FILE).exists()
    with pytest.raises(ValueError, match="no entry for pairs"):
        layout.write_study(tmp_path, "s", [pair], {})


@pytest.mark.parametrize(
    ("damage", "error", "message"),
    [
        (lambda d: shutil.rmtree(d), FileNotFoundError, "is not a study folder"),
        (lambda d: (d / "study.json").unlink(), FileNotFoundError, r"study.json is missing"),
        (lambda d: (d / "key.json").unlink(), FileNotFoundError, r"key.json is missing"),
        (
            lambda d: (d / "videos" / "p03_R.mp4").unlink(),
            FileNotFoundError,
            r"p03_R.mp4: video of pair p03 \(right\) is missing",
        ),
        (
            lambda d: edit_json(d / "study.json", lambda s: s["pairs"][1].update(id="p01")),
            ValueError,
            r"study.json: pair ids \['p01'\] occur more than once",
        ),
        (
            lambda d: edit_json(d / "study.json", lambda s: s["pairs"][0].update(kind="smooth")),
            ValueError,
            r"study.json: pair p01: kind 'smooth' is not one of \('regular', 'non_smooth'\)",
        ),
        (
            lambda d: edit_json(
                d / "study.json", lambda s: s["pairs"][0].update(left="../key.json")
            ),
            ValueError,
            r"pair p01: left '../key.json' must be 'videos/<file name>'",
        ),
        (
            lambda d: edit_json(d / "key.json", lambda k: k["pairs"].pop("p04")),
            ValueError,
            r"key.json: no entry for pairs \['p04'\]",
        ),
        (
            lambda d: edit_json(d / "key.json", lambda k: k["pairs"]["p02"].update(left="left")),
            ValueError,
            r"key.json: pair p02: left 'left' is not one of \('imitation', 'no_imitation'\)",
        ),
        (
            lambda d: edit_json(d / "key.json", lambda k: k["pairs"]["p02"].update(seed="1")),
            ValueError,
            r"key.json: pair p02: seed must be an integer",
        ),
        (
            lambda d: (d / "study.json").write_text("{"),
            ValueError,
            r"study.json: not valid JSON",
        ),
    ],
)
def test_read_study_names_the_file_and_the_problem(study, damage, error, message):
    damage(study.dir)
    with pytest.raises(error, match=message):
        layout.read_study(study.dir)


# --------------------------------------------------------------------- store
def test_store_is_idempotent_and_refuses_a_different_answer(tmp_path):
    answers = store.AnswerStore(tmp_path / "a.sqlite")
    assert answers.submit("ann", "p01", 3) == "stored"
    assert answers.submit("ann", "p01", 3) == "duplicate"
    with pytest.raises(store.AnswerConflict, match="already answered pair p01 with 3"):
        answers.submit("ann", "p01", 1)
    assert answers.submit("bob", "p01", 1) == "stored"
    for bad in (5, -1, True):
        with pytest.raises(ValueError, match="answer must be an integer 0..4"):
            answers.submit("ann", "p02", bad)
    assert answers.answered("ann") == {"p01"} and answers.answered("eve") == set()
    rows = answers.all_answers()
    assert [(r.rater, r.pair_id, r.answer) for r in rows] == [("ann", "p01", 3), ("bob", "p01", 1)]
    assert rows[0].submitted_at <= rows[1].submitted_at <= time.time()


def test_store_survives_a_killed_writer(tmp_path):
    """An acknowledged answer is in the file after its process died by SIGKILL."""
    path = tmp_path / "a.sqlite"
    # Loaded by path: the store needs only the standard library, the package imports JAX.
    code = (
        "import importlib.util, os, signal, sys\n"
        "spec = importlib.util.spec_from_file_location('answer_store', sys.argv[1])\n"
        "m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m)\n"
        "s = m.AnswerStore(sys.argv[2])\n"
        "print(s.submit('ann', 'p01', 4), s.submit('ann', 'p02', 0), flush=True)\n"
        "os.kill(os.getpid(), signal.SIGKILL)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, store.__file__, str(path)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == -signal.SIGKILL and done.stdout.split() == ["stored", "stored"]
    reopened = store.AnswerStore(path)
    assert [(r.pair_id, r.answer) for r in reopened.all_answers()] == [("p01", 4), ("p02", 0)]
    import sqlite3

    with sqlite3.connect(path) as db:
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_store_takes_concurrent_answers(tmp_path):
    answers = store.AnswerStore(tmp_path / "a.sqlite")
    results: list[str] = []

    def rate(rater: str) -> None:
        for i in range(10):
            results.append(answers.submit(rater, f"p{i:02d}", i % 5))
            results.append(answers.submit(rater, f"p{i:02d}", i % 5))

    threads = [threading.Thread(target=rate, args=(f"r{k}",)) for k in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(results) == ["duplicate"] * 60 + ["stored"] * 60
    assert len(answers.all_answers()) == 60


# ---------------------------------------------------------------- statistics
def t_p_by_integration(t: float, df: int) -> float:
    """Two-sided p of Student's t by integrating its density (independent of scipy)."""
    x = np.linspace(0.0, abs(t), 200_001)
    log_c = math.lgamma((df + 1) / 2) - math.lgamma(df / 2) - 0.5 * math.log(df * math.pi)
    pdf = np.exp(log_c - (df + 1) / 2 * np.log1p(x * x / df))
    return 1.0 - 2.0 * float(np.trapezoid(pdf, x))


def test_t_test_against_a_hand_computed_t_and_integration():
    """The one-sample t-test against the formula and its density integrated (scipy's
    implementation is what the report uses; the edge cases are the report's own)."""
    for sample in ([2, 1, 1, 0, 2, -1, 1, 2], [-2, -1, 0, -1, 1, -2, -2, 0, -1, -1, 2]):
        x = np.asarray(sample, float)
        t_hand = x.mean() / (x.std(ddof=1) / math.sqrt(len(x)))
        t, p = report.one_sample_t_test(sample)
        assert t == pytest.approx(t_hand)
        assert p == pytest.approx(t_p_by_integration(t_hand, len(x) - 1), abs=1e-8)
    assert report.one_sample_t_test([1, 1, 1]) == (math.inf, 0.0)
    assert report.one_sample_t_test([0, 0]) == (0.0, 1.0)
    assert all(math.isnan(v) for v in report.one_sample_t_test([2]))


def test_sign_test_by_hand():
    # 5 positive, 1 negative, 1 tie: p = 2 (C(6,0) + C(6,1)) / 2^6.
    assert report.sign_test([1, 2, 1, 1, 2, -1, 0]) == pytest.approx(14 / 64)
    assert report.sign_test([1, -1]) == 1.0
    assert report.sign_test([0, 0]) == 1.0
    assert report.sign_test([2] * 10) == pytest.approx(2 / 1024)


# -------------------------------------------------------------------- report
# answers[rater][pair] and the signed values they mean with PAIRS' left policies.
ANSWERS = {
    "a": {"p01": 0, "p02": 0, "p03": 1, "p04": 4, "p05": 2},
    "b": {"p01": 1, "p02": 3, "p03": 2, "p04": 3, "p05": 4},
}
VALUES = {
    "a": {"p01": 2, "p02": -2, "p03": 1, "p04": 2, "p05": 0},
    "b": {"p01": 1, "p02": 1, "p03": 0, "p04": 1, "p05": -2},
}


def read_table(path: Path) -> dict[tuple[str, str], dict[str, str]]:
    with path.open() as f:
        return {(r["task"], r["kind"]): r for r in csv.DictReader(f)}


def check_table(table: dict[tuple[str, str], dict[str, str]], values: dict[str, dict[str, int]]):
    """Every row of table1.csv against the values computed here from ``values``."""
    kinds = {p[0]: (p[1], p[2]) for p in PAIRS}
    for (task, kind), row in table.items():
        x = np.asarray(
            [
                v
                for by_pair in values.values()
                for pid, v in by_pair.items()
                if task in ("all", kinds[pid][0]) and kind in ("all", kinds[pid][1])
            ],
            float,
        )
        assert int(row["n"]) == x.size, (task, kind)
        assert float(row["mean"]) == pytest.approx(x.mean()), (task, kind)
        for v in (-2, -1, 0, 1, 2):
            assert float(row[report.share_key(v)]) == pytest.approx((x == v).mean())
        if x.size > 1:
            assert float(row["se"]) == pytest.approx(x.std(ddof=1) / math.sqrt(x.size))
        if x.size > 1 and x.std() > 0:
            t = x.mean() / (x.std(ddof=1) / math.sqrt(x.size))
            assert float(row["t"]) == pytest.approx(t)
            assert float(row["p_t"]) == pytest.approx(t_p_by_integration(t, x.size - 1), abs=1e-7)


def test_report_table1_by_hand(study, tmp_path):
    answers = store.AnswerStore(study.answers_path)
    for rater, by_pair in ANSWERS.items():
        for pid, answer in by_pair.items():
            answers.submit(rater, pid, answer)
    rows = report.write_report(study.dir, tmp_path / "out")
    table = read_table(tmp_path / "out" / report.CSV_FILE)
    expected_groups = {
        ("handshake", "regular"), ("handshake", "non_smooth"), ("handshake", "all"),
        ("handclap", "regular"), ("handclap", "all"),
        ("et", "regular"), ("et", "non_smooth"), ("et", "all"),
        ("all", "regular"), ("all", "non_smooth"), ("all", "all"),
    }  # fmt: skip
    assert set(table) == expected_groups and len(rows) == len(expected_groups)
    check_table(table, VALUES)
    # A few cells spelled out: handshake regular is (+2, +1); everything sums to 4 over 10.
    hs = table[("handshake", "regular")]
    assert float(hs["mean"]) == 1.5 and float(hs["se"]) == pytest.approx(0.5)
    assert float(hs["p_t"]) == pytest.approx(1 - 2 * math.atan(3) / math.pi)  # t = 3, df = 1
    everything = table[("all", "all")]
    assert (everything["n"], everything["pairs"], everything["raters"]) == ("10", "5", "2")
    assert float(everything["mean"]) == pytest.approx(0.4)
    assert float(everything["share_+1"]) == pytest.approx(0.4)
    assert float(everything["share_-1"]) == 0.0
    record = json.loads((tmp_path / "out" / report.JSON_FILE).read_text())
    assert record["answers"] == 10 and record["raters"] == 2 and len(record["rows"]) == 11
    assert (tmp_path / "out" / report.PLOT_FILE).stat().st_size > 1000


def test_report_refuses_without_answers_or_with_foreign_answers(study):
    with pytest.raises(ValueError, match="no answers yet"):
        report.write_report(study.dir)
    store.AnswerStore(study.answers_path).submit("a", "p99", 1)
    with pytest.raises(ValueError, match=r"answers to pairs \['p99'\] that .*study.json does not"):
        report.write_report(study.dir)


# -------------------------------------------------------------------- server
class Client:
    """Raw HTTP requests (paths sent as written, not normalised)."""

    def __init__(self, port: int) -> None:
        self.port = port

    def request(self, method: str, path: str, body: bytes | None = None, headers=None):
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=10)
        try:
            conn.request(method, path, body=body, headers=headers or {})
            response = conn.getresponse()
            return response.status, dict(response.getheaders()), response.read()
        finally:
            conn.close()

    def post(self, content, raw: bytes | None = None, content_type: str = "application/json"):
        body = raw if raw is not None else json.dumps(content).encode()
        status, _, data = self.request("POST", "/api/answer", body, {"Content-Type": content_type})
        return status, json.loads(data)

    def get_json(self, path: str):
        status, _, data = self.request("GET", path)
        return status, json.loads(data)


@pytest.fixture
def client(study):
    httpd = server.make_server(study.dir, port=0, log=False)
    thread = threading.Thread(target=httpd.serve_forever, args=(0.05,), daemon=True)
    thread.start()
    try:
        yield Client(httpd.server_address[1])
    finally:
        httpd.shutdown()
        httpd.server_close()


def test_server_page_and_public_study(client, study):
    status, headers, page = client.request("GET", "/")
    assert status == 200 and headers["Content-Type"].startswith("text/html")
    text = page.decode()
    for element in (
        "rater",
        "start",
        "left-video",
        "right-video",
        "submit",
        "progress",
        "done",
        "error",
    ):
        assert f'id="{element}"' in text
    for i, label in enumerate(layout.SCALE):
        assert f'id="answer-{i}"' in text and label in text
    assert "http://" not in text and "https://" not in text  # nothing from elsewhere
    status, public = client.get_json("/api/study")
    assert status == 200 and public == study.public()
    assert "imitation" not in json.dumps(public)


def test_page_escapes_the_study_name(study):
    import dataclasses

    page = server.render_page(dataclasses.replace(study, name="<b>A&B</b> {{SCALE}}")).decode()
    assert "<title>&lt;b&gt;A&amp;B&lt;/b&gt; {{SCALE}}</title>" in page
    assert page.count('id="answer-0"') == 1


def test_server_next_follows_the_rater_order_and_ends_done(client, study):
    order = server.rater_order("ann", [p.id for p in study.pairs])
    assert sorted(order) == sorted(p.id for p in study.pairs)
    for k, pid in enumerate(order):
        status, step = client.get_json("/api/next?rater=ann")
        assert status == 200 and not step["done"]
        assert (step["pair"]["id"], step["answered"], step["total"]) == (pid, k, len(order))
        assert client.post({"rater": "ann", "pair_id": pid, "answer": k % 5}) == (
            200,
            {"status": "stored"},
        )
    assert client.get_json("/api/next?rater=ann") == (
        200,
        {"done": True, "answered": 5, "total": 5},
    )
    assert client.get_json("/api/next?rater=")[0] == 400


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (b"{not json", "body is not valid JSON"),
        (b"[1, 2]", "body must be a JSON object"),
        (json.dumps({"rater": "ann", "answer": 1}).encode(), r"missing fields \['pair_id'\]"),
        (json.dumps({"rater": "ann", "pair_id": "p99", "answer": 1}).encode(), "unknown pair_id 'p99'"),
        (json.dumps({"rater": "ann", "pair_id": "p01", "answer": 5}).encode(), "answer must be an integer 0..4, got 5"),
        (json.dumps({"rater": "ann", "pair_id": "p01", "answer": "2"}).encode(), "answer must be an integer 0..4, got '2'"),
        (json.dumps({"rater": "ann", "pair_id": "p01", "answer": 2.0}).encode(), "answer must be an integer"),
        (json.dumps({"rater": "ann", "pair_id": "p01", "answer": True}).encode(), "answer must be an integer"),
        (json.dumps({"rater": "", "pair_id": "p01", "answer": 1}).encode(), "rater must be a non-empty string"),
        (json.dumps({"rater": "  ", "pair_id": "p01", "answer": 1}).encode(), "rater must be a non-empty string"),
        (json.dumps({"rater": 7, "pair_id": "p01", "answer": 1}).encode(), "rater must be a non-empty string"),
        (json.dumps({"rater": "x" * 65, "pair_id": "p01", "answer": 1}).encode(), "at most 64"),
    ],
)  # fmt: skip
def test_server_rejects_bad_answers_with_a_message(client, study, body, message):
    status, reply = client.post(None, raw=body)
    assert status == 400 and set(reply) == {"error"}
    assert re.search(message, reply["error"]), reply
    assert store.read_answers(study.answers_path) == []


def test_server_conflict_duplicate_size_and_type(client, study):
    answer = {"rater": "ann", "pair_id": "p02", "answer": 1}
    assert client.post(answer) == (200, {"status": "stored"})
    assert client.post(answer) == (200, {"status": "duplicate"})
    status, reply = client.post(answer | {"answer": 3})
    assert status == 409 and "already answered pair p02 with 1" in reply["error"]
    status, reply = client.post(None, raw=b" " * 20_000)
    assert status == 413 and "at most 10000" in reply["error"]
    assert client.post(answer, content_type="text/plain")[0] == 415
    conn = http.client.HTTPConnection("127.0.0.1", client.port, timeout=10)
    conn.putrequest("POST", "/api/answer")  # no Content-Length
    conn.putheader("Content-Type", "application/json")
    conn.endheaders()
    response = conn.getresponse()
    assert response.status == 411 and "Content-Length" in json.loads(response.read())["error"]
    conn.close()
    rows = store.read_answers(study.answers_path)
    assert [(r.rater, r.pair_id, r.answer) for r in rows] == [("ann", "p02", 1)]


@pytest.mark.parametrize(
    "path",
    [
        "/videos/../key.json",
        "/videos/%2e%2e/key.json",
        "/videos/%2e%2e%2fkey.json",
        "/videos/..%2Fanswers.sqlite",
        "/videos//etc/passwd",
        "/videos/%2Fetc%2Fpasswd",
        "/videos/",
        "/videos/p01_L.mp4/",
        "/videos/other.mp4",
        "/key.json",
        "/answers.sqlite",
        "/study.json",
        "/videos/../study.json",
        "/../key.json",
        "/api/../key.json",
    ],
)
def test_server_serves_no_file_but_the_study_videos(client, study, path):
    status, _, body = client.request("GET", path)
    assert status == 404, path
    assert b"seed" not in body and b"imitation" not in body


def test_server_videos_with_ranges(client, study):
    data = (study.dir / "videos" / "p01_L.mp4").read_bytes()
    status, headers, body = client.request("GET", "/videos/p01_L.mp4")
    assert status == 200 and body == data
    assert headers["Content-Type"] == "video/mp4" and headers["Content-Length"] == str(len(data))
    status, headers, body = client.request(
        "GET", "/videos/p01_L.mp4", headers={"Range": "bytes=0-9"}
    )
    assert status == 206 and body == data[:10]
    assert headers["Content-Range"] == f"bytes 0-9/{len(data)}"
    status, _, body = client.request("GET", "/videos/p01_L.mp4", headers={"Range": "bytes=-7"})
    assert status == 206 and body == data[-7:]
    status, _, body = client.request("GET", "/videos/p01_L.mp4", headers={"Range": "bytes=100-"})
    assert status == 206 and body == data[100:]
    status, _, _ = client.request(
        "GET", "/videos/p01_L.mp4", headers={"Range": f"bytes={len(data)}-"}
    )
    assert status == 416
    status, headers, body = client.request("HEAD", "/videos/p01_L.mp4")
    assert status == 200 and body == b"" and headers["Content-Length"] == str(len(data))


def test_server_refuses_a_video_link_that_leaves_the_folder(study):
    video = study.dir / "videos" / "p05_R.mp4"
    video.unlink()
    video.symlink_to(study.dir / "key.json")
    httpd = server.make_server(study.dir, port=0, log=False)
    thread = threading.Thread(target=httpd.serve_forever, args=(0.05,), daemon=True)
    thread.start()
    try:
        status, _, body = Client(httpd.server_address[1]).request("GET", "/videos/p05_R.mp4")
        assert status == 404 and b"seed" not in body
    finally:
        httpd.shutdown()
        httpd.server_close()


def test_cli_report_and_missing_make(study, tmp_path):
    store.AnswerStore(study.answers_path).submit("a", "p01", 0)
    from mjx_hands.study.__main__ import main

    assert main(["report", str(study.dir), "--out", str(tmp_path / "r")]) == 0
    assert read_table(tmp_path / "r" / report.CSV_FILE)[("all", "all")]["mean"] == "2.0"
    assert main(["report", str(tmp_path / "nowhere")]) == 2
    assert main(["unknown"]) == 2


# ------------------------------------------------------------------- browser
def browser_or_skip() -> tuple[str, str]:
    """(chromium, chromedriver) paths; skip without them, but fail in CI (CI set)."""
    chromium = next(
        (p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None
    )
    driver = shutil.which("chromedriver")
    missing = [n for n, p in (("chromium", chromium), ("chromedriver", driver)) if p is None]
    if importlib.util.find_spec("selenium") is None:
        missing.append("selenium (pip install -e '.[test]')")
    if missing:
        message = f"browser test needs {', '.join(missing)} (Debian: apt-get install chromium chromium-driver)"
        if os.environ.get("CI"):
            pytest.fail(f"{message}; CI must run it, not skip it")
        pytest.skip(message)
    assert chromium is not None and driver is not None
    return chromium, driver


def start_server(study_dir: Path, port: int, log: Path) -> tuple[subprocess.Popen, int]:
    """``python -m mjx_hands.study serve`` in its own process; (process, bound port)."""
    seen = log.stat().st_size if log.exists() else 0  # lines of earlier runs do not count
    with log.open("a") as out:
        process = subprocess.Popen(
            [sys.executable, "-m", "mjx_hands.study", "serve", str(study_dir), "--port", str(port)],
            stdout=out,
            stderr=subprocess.STDOUT,
            cwd=ROOT,
        )
    deadline = time.monotonic() + 120  # the package imports JAX: seconds on a busy machine
    while time.monotonic() < deadline:
        for line in log.read_bytes()[seen:].decode(errors="replace").splitlines():
            if line.startswith("serving at "):
                bound = urllib.parse.urlsplit(line.removeprefix("serving at ")).port
                assert bound is not None and port in (0, bound), line
                return process, bound
        if process.poll() is not None:
            raise AssertionError(f"server exited with {process.returncode}:\n{log.read_text()}")
        time.sleep(0.1)
    process.kill()
    raise AssertionError(f"server did not start:\n{log.read_text()}")


@pytest.mark.browser
def test_browser_rates_a_study_across_a_server_crash(study, tmp_path):
    chromium, chromedriver = browser_or_skip()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for arg in (
        "--headless=new",
        "--no-sandbox",  # CI containers run as root
        "--disable-dev-shm-usage",
        "--autoplay-policy=no-user-gesture-required",
        "--window-size=1200,900",
        f"--user-data-dir={tmp_path / 'profile'}",
    ):
        options.add_argument(arg)
    log = tmp_path / "server.log"
    process, port = start_server(study.dir, 0, log)
    driver = webdriver.Chrome(options=options, service=Service(executable_path=chromedriver))
    wait = WebDriverWait(driver, 30)
    order = server.rater_order("carol", [p.id for p in study.pairs])
    # The answer given to each pair, in the order carol sees them.
    given = dict(zip(order, (0, 4, 1, 3, 2)))

    def element(id_: str):
        return driver.find_element(By.ID, id_)

    def current_pair() -> str:
        wait.until(lambda d: element("study").is_displayed())
        return element("study").get_attribute("data-pair")

    def answer_current(k: int) -> None:
        pid = order[k]
        wait.until(lambda d: element("progress").text == f"{k + 1} / 5")
        assert current_pair() == pid
        pair = study.pair(pid)
        assert element("left-video").get_attribute("src").endswith(pair.left)
        assert element("right-video").get_attribute("src").endswith(pair.right)
        element(f"answer-{given[pid]}").click()
        element("submit").click()

    try:
        driver.get(f"http://127.0.0.1:{port}/")
        wait.until(lambda d: element("rater").is_displayed())
        element("rater").send_keys("carol")
        element("start").click()
        # The browser decodes the served mp4 (64x64), not just requests it.
        wait.until(
            lambda d: (
                d.execute_script("return document.getElementById('left-video').videoWidth") == 64
            )
        )
        answer_current(0)
        answer_current(1)
        wait.until(lambda d: element("progress").text == "3 / 5")

        process.send_signal(signal.SIGKILL)
        process.wait(timeout=10)
        rows = store.read_answers(study.answers_path)
        assert [(r.rater, r.pair_id, r.answer) for r in rows] == [
            ("carol", pid, given[pid]) for pid in order[:2]
        ]
        # Answering while the server is down says so and keeps the rater on the pair.
        element(f"answer-{given[order[2]]}").click()
        element("submit").click()
        wait.until(lambda d: element("error").is_displayed())
        assert "not saved" in element("error").text
        assert element("progress").text == "3 / 5"

        process, _ = start_server(study.dir, port, log)
        driver.refresh()  # the rater's name is remembered: straight back to pair 3
        wait.until(lambda d: element("progress").text == "3 / 5")
        assert current_pair() == order[2] and not element("error").is_displayed()
        assert not element("intro").is_displayed()
        for k in (2, 3, 4):
            answer_current(k)
        wait.until(lambda d: element("done").is_displayed())
        assert "Thank you" in element("done").text
        assert not element("study").is_displayed()
    finally:
        driver.quit()
        process.kill()
        process.wait(timeout=10)

    rows = store.read_answers(study.answers_path)
    assert sorted((r.rater, r.pair_id, r.answer) for r in rows) == sorted(
        ("carol", pid, a) for pid, a in given.items()
    )
    # By hand: answer 0 means +2 for the left policy, 4 means +2 for the right one.
    lefts = {p[0]: p[3] for p in PAIRS}
    values = {
        "carol": {
            pid: (2 - a) if lefts[pid] == "imitation" else (a - 2) for pid, a in given.items()
        }
    }
    report.write_report(study.dir, tmp_path / "report")
    table = read_table(tmp_path / "report" / report.CSV_FILE)
    check_table(table, values)
    assert table[("all", "all")]["n"] == "5"

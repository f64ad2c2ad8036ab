"""The raters' answers in SQLite: one row per (rater, pair), durable once acknowledged.

    answers(rater TEXT, pair_id TEXT, answer INTEGER 0..4, submitted_at REAL unix seconds,
            PRIMARY KEY (rater, pair_id))

Every call opens its own connection (the server answers requests on many threads), in
WAL mode with ``synchronous=FULL``: an answer the server acknowledged has been committed
and synced, so it survives the server being killed, or the machine losing power.
"""

from __future__ import annotations

import os
import sqlite3
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Literal, NamedTuple

SCHEMA = """
CREATE TABLE IF NOT EXISTS answers (
    rater TEXT NOT NULL,
    pair_id TEXT NOT NULL,
    answer INTEGER NOT NULL CHECK (answer BETWEEN 0 AND 4),
    submitted_at REAL NOT NULL,
    PRIMARY KEY (rater, pair_id)
)
"""


class Answer(NamedTuple):
    """One stored row."""

    rater: str
    pair_id: str
    answer: int
    submitted_at: float


class AnswerConflict(ValueError):
    """The rater already gave another answer to this pair (answers are final)."""


class AnswerStore:
    """Answers of one study in the SQLite file ``path`` (created with its table)."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        with self._connect() as db:
            # WAL persists in the file; the other settings are per connection.
            db.execute("PRAGMA journal_mode=WAL")
            db.execute(SCHEMA)

    @contextmanager
    def _connect(self) -> Iterator[sqlite3.Connection]:
        # isolation_level=None: transactions are spelled out (BEGIN IMMEDIATE below).
        db = sqlite3.connect(self.path, timeout=30.0, isolation_level=None)
        try:
            db.execute("PRAGMA synchronous=FULL")
            yield db
        finally:
            db.close()

    def submit(self, rater: str, pair_id: str, answer: int) -> Literal["stored", "duplicate"]:
        """Store ``answer`` (0..4) of ``rater`` to ``pair_id``, committed before returning.

        "stored" for a new answer; "duplicate" when the same answer is already stored
        (a resent request: nothing changes). Raises AnswerConflict when the rater
        already gave a different answer to the pair, ValueError for an answer outside 0..4.
        """
        if isinstance(answer, bool) or not isinstance(answer, int) or not 0 <= answer <= 4:
            raise ValueError(f"answer must be an integer 0..4, got {answer!r}")
        with self._connect() as db:
            # IMMEDIATE takes the write lock first, so check-then-insert is atomic.
            db.execute("BEGIN IMMEDIATE")
            try:
                row = db.execute(
                    "SELECT answer FROM answers WHERE rater = ? AND pair_id = ?", (rater, pair_id)
                ).fetchone()
                if row is None:
                    db.execute(
                        "INSERT INTO answers VALUES (?, ?, ?, ?)",
                        (rater, pair_id, answer, time.time()),
                    )
                db.execute("COMMIT")
            except BaseException:
                db.execute("ROLLBACK")
                raise
        if row is None:
            return "stored"
        if row[0] == answer:
            return "duplicate"
        raise AnswerConflict(
            f"rater {rater!r} already answered pair {pair_id} with {row[0]}; "
            f"answers are final, {answer} was not stored"
        )

    def answered(self, rater: str) -> set[str]:
        """Ids of the pairs ``rater`` answered."""
        with self._connect() as db:
            rows = db.execute("SELECT pair_id FROM answers WHERE rater = ?", (rater,)).fetchall()
        return {r[0] for r in rows}

    def all_answers(self) -> list[Answer]:
        """Every stored answer, ordered by submission time."""
        with self._connect() as db:
            rows = db.execute(
                "SELECT rater, pair_id, answer, submitted_at FROM answers "
                "ORDER BY submitted_at, rater, pair_id"
            ).fetchall()
        return [Answer(*r) for r in rows]


def read_answers(path: str | os.PathLike[str]) -> list[Answer]:
    """Every answer in the database ``path``; [] when it does not exist (nothing created)."""
    if not Path(path).is_file():
        return []
    return AnswerStore(path).all_answers()

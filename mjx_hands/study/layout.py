"""The study folder: what raters may see, the secret key, the videos.

    STUDY_DIR/study.json     public: {"name", "format": 1, "scale": [5 labels],
                             "pairs": [{"id", "task", "kind", "left", "right"}, ...]}
    STUDY_DIR/key.json       secret, never served: {"pairs": {id: {"left": "imitation" |
                             "no_imitation", "seed": int, ...free extra fields}}}
    STUDY_DIR/videos/        the mp4 files that "left"/"right" name ("videos/p01_L.mp4")
    STUDY_DIR/answers.sqlite the raters' answers (written by the server, see ``store``)

Answers are indices 0..4 into ``SCALE`` (0: the left video looks much more natural,
4: the right one does); :func:`answer_value` turns one into the signed preference for
the imitation policy, -2..+2, with the key's left/right assignment.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

FORMAT = 1
STUDY_FILE = "study.json"
KEY_FILE = "key.json"
VIDEOS_DIR = "videos"
ANSWERS_FILE = "answers.sqlite"

SCALE: tuple[str, ...] = (
    "left much more natural",
    "left somewhat more natural",
    "both equally natural",
    "right somewhat more natural",
    "right much more natural",
)
KINDS: tuple[str, ...] = ("regular", "non_smooth")
POLICIES: tuple[str, ...] = ("imitation", "no_imitation")

# Pair ids travel in URLs and JSON; plain names keep them unambiguous.
_ID_PATTERN = re.compile(r"[A-Za-z0-9_-]{1,64}")
# A video is named by one plain file name inside videos/ (what the server serves).
_VIDEO_NAME_PATTERN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}")


@dataclasses.dataclass(frozen=True)
class Pair:
    """One rated pair: two videos of ``task`` from the same start.

    ``left``/``right`` are paths relative to the study folder, ``videos/<file name>``;
    ``kind`` is ``regular`` or ``non_smooth`` (a start far from every demonstration).
    """

    id: str
    task: str
    kind: str
    left: str
    right: str

    def public(self) -> dict[str, str]:
        """The pair as study.json stores it and the page sees it."""
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class KeyEntry:
    """The hidden side of one pair: which policy plays left, its seed, extra fields."""

    left: str
    seed: int
    extra: Mapping[str, Any] = dataclasses.field(default_factory=dict)

    def as_json(self) -> dict[str, Any]:
        return {**self.extra, "left": self.left, "seed": self.seed}


@dataclasses.dataclass(frozen=True)
class Study:
    """A validated study folder: ``pairs`` in study order, ``key`` by pair id."""

    dir: Path
    name: str
    scale: tuple[str, ...]
    pairs: tuple[Pair, ...]
    key: Mapping[str, KeyEntry]

    def pair(self, pair_id: str) -> Pair | None:
        """The pair with this id, or None."""
        return next((p for p in self.pairs if p.id == pair_id), None)

    def public(self) -> dict[str, Any]:
        """What the page may see: study.json's content, no key."""
        return {
            "name": self.name,
            "format": FORMAT,
            "scale": list(self.scale),
            "pairs": [p.public() for p in self.pairs],
        }

    @property
    def answers_path(self) -> Path:
        return self.dir / ANSWERS_FILE

    @property
    def videos_dir(self) -> Path:
        return self.dir / VIDEOS_DIR


def pair_id(index: int) -> str:
    """Conventional id of the pair at 0-based ``index``: ``p01``, ``p02``, ..."""
    return f"p{index + 1:02d}"


def video_path(pair: str, side: str) -> str:
    """Conventional study-relative video path of one side: ``videos/p01_L.mp4``."""
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    return f"{VIDEOS_DIR}/{pair}_{'L' if side == 'left' else 'R'}.mp4"


def answer_value(answer_index: int, left: str) -> int:
    """Signed preference for the imitation policy, -2..+2, of answer ``answer_index``
    (0 = left much more natural ... 4 = right much more natural) when the policy
    ``left`` ("imitation" or "no_imitation") played on the left."""
    is_int = isinstance(answer_index, int) and not isinstance(answer_index, bool)
    if not (is_int and 0 <= answer_index < len(SCALE)):
        raise ValueError(f"answer must be an integer 0..4, got {answer_index!r}")
    if left not in POLICIES:
        raise ValueError(f"left must be one of {POLICIES}, got {left!r}")
    toward_left = 2 - answer_index  # +2: left much more natural
    return toward_left if left == "imitation" else -toward_left


# ------------------------------------------------------------------ validation
def _require(condition: bool, where: Path | str, message: str) -> None:
    if not condition:
        raise ValueError(f"{where}: {message}")


def _parse_pair(raw: Any, index: int, where: Path) -> Pair:
    at = f"pairs[{index}]"
    _require(isinstance(raw, Mapping), where, f"{at} must be an object, got {raw!r}")
    fields = {f.name for f in dataclasses.fields(Pair)}
    missing = sorted(fields - raw.keys())
    _require(not missing, where, f"{at} misses {missing}; expected fields {sorted(fields)}")
    for name in sorted(fields):
        _require(
            isinstance(raw[name], str) and raw[name] != "",
            where,
            f"{at}.{name} must be a non-empty string, got {raw[name]!r}",
        )
    pair = Pair(**{name: raw[name] for name in fields})
    _require(
        _ID_PATTERN.fullmatch(pair.id) is not None,
        where,
        f"{at}.id {pair.id!r} must be 1-64 letters, digits, '_' or '-'",
    )
    _require(pair.kind in KINDS, where, f"pair {pair.id}: kind {pair.kind!r} is not one of {KINDS}")
    for side in ("left", "right"):
        path = getattr(pair, side)
        folder, _, name = path.partition("/")
        _require(
            folder == VIDEOS_DIR and _VIDEO_NAME_PATTERN.fullmatch(name) is not None,
            where,
            f"pair {pair.id}: {side} {path!r} must be '{VIDEOS_DIR}/<file name>' "
            "(a plain file name: letters, digits, '_', '-', '.')",
        )
    return pair


def parse_study(
    raw: Any, where: Path | str = STUDY_FILE
) -> tuple[str, tuple[str, ...], tuple[Pair, ...]]:
    """(name, scale labels, pairs) of study.json's content; ValueError naming what is wrong."""
    _require(isinstance(raw, Mapping), where, "must hold a JSON object")
    _require(
        raw.get("format") == FORMAT,
        where,
        f"format must be {FORMAT}, got {raw.get('format')!r}",
    )
    name = raw.get("name")
    _require(
        isinstance(name, str) and name != "",
        where,
        f"name must be a non-empty string, got {name!r}",
    )
    scale = raw.get("scale")
    _require(
        isinstance(scale, list)
        and len(scale) == len(SCALE)
        and all(isinstance(s, str) for s in scale),
        where,
        f"scale must be a list of {len(SCALE)} label strings, got {scale!r}",
    )
    raw_pairs = raw.get("pairs")
    _require(
        isinstance(raw_pairs, list) and len(raw_pairs) > 0,
        where,
        f"pairs must be a non-empty list, got {raw_pairs!r}",
    )
    pairs = tuple(_parse_pair(p, i, Path(where)) for i, p in enumerate(raw_pairs))
    ids = [p.id for p in pairs]
    duplicated = sorted({i for i in ids if ids.count(i) > 1})
    _require(
        not duplicated, where, f"pair ids {duplicated} occur more than once; ids must be unique"
    )
    return name, tuple(scale), pairs


def parse_key(
    raw: Any, pair_ids: Sequence[str], where: Path | str = KEY_FILE
) -> dict[str, KeyEntry]:
    """Key entries by pair id of key.json's content, one for each of ``pair_ids``."""
    _require(
        isinstance(raw, Mapping) and isinstance(raw.get("pairs"), Mapping),
        where,
        'must hold {"pairs": {pair id: {"left": ..., "seed": ...}}}',
    )
    entries = raw["pairs"]
    missing = [i for i in pair_ids if i not in entries]
    _require(
        not missing, where, f"no entry for pairs {missing}; every pair of study.json needs one"
    )
    unknown = sorted(set(entries) - set(pair_ids))
    _require(not unknown, where, f"entries for pairs {unknown} that study.json does not list")
    key = {}
    for pid in pair_ids:
        entry = entries[pid]
        _require(isinstance(entry, Mapping), where, f"pair {pid}: entry must be an object")
        left, seed = entry.get("left"), entry.get("seed")
        _require(left in POLICIES, where, f"pair {pid}: left {left!r} is not one of {POLICIES}")
        _require(
            isinstance(seed, int) and not isinstance(seed, bool),
            where,
            f"pair {pid}: seed must be an integer, got {seed!r}",
        )
        extra = {k: v for k, v in entry.items() if k not in ("left", "seed")}
        key[pid] = KeyEntry(left=left, seed=seed, extra=extra)
    return key


def _check_videos(study_dir: Path, pairs: Sequence[Pair]) -> None:
    for pair in pairs:
        for side in ("left", "right"):
            path = study_dir / getattr(pair, side)
            if not path.is_file():
                raise FileNotFoundError(
                    f"{path}: video of pair {pair.id} ({side}) is missing; expected an mp4 file "
                    f"in {study_dir / VIDEOS_DIR}"
                )


def _read_json(path: Path) -> Any:
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing: {path.parent} is not a complete study folder")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not valid JSON ({err})") from None


def read_study(study_dir: str | os.PathLike[str]) -> Study:
    """The validated study in ``study_dir`` (study.json, key.json, every video present).

    Raises FileNotFoundError for a missing folder, file or video and ValueError, naming
    the file and the field, for content that does not follow the layout.
    """
    study_dir = Path(study_dir)
    if not study_dir.is_dir():
        raise FileNotFoundError(f"{study_dir} is not a study folder (no such directory)")
    study_path = study_dir / STUDY_FILE
    name, scale, pairs = parse_study(_read_json(study_path), study_path)
    key_path = study_dir / KEY_FILE
    key = parse_key(_read_json(key_path), [p.id for p in pairs], key_path)
    _check_videos(study_dir, pairs)
    return Study(dir=study_dir, name=name, scale=scale, pairs=pairs, key=key)


def _write_json_atomic(path: Path, content: Any) -> None:
    """Write via a temporary file and rename so a reader never sees half a file."""
    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("w") as f:
        json.dump(content, f, indent=2)
        f.write("\n")
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def write_study(
    study_dir: str | os.PathLike[str],
    name: str,
    pairs: Sequence[Pair | Mapping[str, str]],
    key: Mapping[str, Mapping[str, Any] | KeyEntry],
) -> Study:
    """Write study.json and key.json of a study whose videos are already rendered.

    Arguments:
        study_dir: the study folder; its ``videos/`` must already hold every video that
            ``pairs`` names (render them first, e.g. to ``video_path(pid, "left")``).
        name: the study's title, shown on the page.
        pairs: in the order raters see them (the server shuffles it per rater), each a
            :class:`Pair` or a mapping with the string fields ``id`` (1-64 letters,
            digits, '_', '-'; e.g. ``pair_id(i)`` = "p01"), ``task`` (e.g. "handshake"),
            ``kind`` ("regular" or "non_smooth") and ``left``/``right``
            ("videos/<file name>", e.g. ``video_path("p01", "left")`` =
            "videos/p01_L.mp4").
        key: by pair id, a mapping ``{"left": "imitation" | "no_imitation", "seed": int,
            ...any extra JSON fields (run dirs, checkpoint steps, start index)}`` or a
            :class:`KeyEntry`; one entry for every pair and no others.

    Everything is validated before anything is written (ValueError / FileNotFoundError
    naming the problem); the JSON files are replaced atomically. Raises FileExistsError
    when ``answers.sqlite`` already exists: its answers belong to the pairs written
    before. Returns the study as :func:`read_study` reads it back.
    """
    study_dir = Path(study_dir)
    if not study_dir.is_dir():
        raise FileNotFoundError(f"{study_dir} is not a study folder (no such directory)")
    answers = study_dir / ANSWERS_FILE
    if answers.exists():
        raise FileExistsError(
            f"{answers} exists: its answers belong to the study written before; move it away "
            "or write the new study to another folder"
        )
    public = {
        "name": name,
        "format": FORMAT,
        "scale": list(SCALE),
        "pairs": [p.public() if isinstance(p, Pair) else dict(p) for p in pairs],
    }
    _, _, parsed = parse_study(public, study_dir / STUDY_FILE)
    secret = {
        "pairs": {
            pid: e.as_json() if isinstance(e, KeyEntry) else dict(e) for pid, e in key.items()
        }
    }
    parse_key(secret, [p.id for p in parsed], study_dir / KEY_FILE)
    _check_videos(study_dir, parsed)
    _write_json_atomic(study_dir / KEY_FILE, secret)
    _write_json_atomic(study_dir / STUDY_FILE, public)
    return read_study(study_dir)

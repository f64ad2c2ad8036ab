"""The study's web server: the rating page, its JSON API and the videos (stdlib only).

    GET  /                      the page (self-contained HTML, inline JS/CSS)
    GET  /api/study             study.json's content (no key)
    GET  /api/next?rater=NAME   {"done": false, "pair": {...}, "answered": k, "total": n}
                                or {"done": true, "answered": n, "total": n}
    POST /api/answer            {"rater", "pair_id", "answer": 0..4} -> {"status": "stored" |
                                "duplicate"}; 400 malformed, 409 a different answer given
                                before, 411 no length, 413 over 10 kB, 415 not JSON
    GET  /videos/NAME           a video the study names (HTTP Range supported)

Anything else is 404: key.json, answers.sqlite and study.json are never served by path.
Each rater sees the pairs in an order of their own (shuffled by a hash of the rater's
name and the pair id, so it survives restarts) to spread order effects over raters.
"""

from __future__ import annotations

import hashlib
import html
import json
import mimetypes
import os
import re
import sys
import urllib.parse
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from typing import Any

from mjx_hands.study import layout, store

MAX_BODY_BYTES = 10_000
MAX_RATER_CHARS = 64
_CHUNK = 1 << 16
_RANGE = re.compile(r"bytes=(\d*)-(\d*)")
# Inline script and style only; media, API calls from this origin; nothing external.
_PAGE_POLICY = (
    "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; "
    "media-src 'self'; connect-src 'self'; img-src 'self'; form-action 'none'; "
    "frame-ancestors 'none'; base-uri 'none'"
)


class RequestError(Exception):
    """A request the API refuses: HTTP ``status`` and a message for the rater."""

    def __init__(self, status: HTTPStatus, message: str) -> None:
        super().__init__(message)
        self.status = status


def rater_order(rater: str, pair_ids: list[str]) -> list[str]:
    """The order in which ``rater`` sees the pairs: a fixed shuffle per rater."""
    return sorted(pair_ids, key=lambda p: hashlib.sha256(f"{rater}\0{p}".encode()).digest())


def check_rater(rater: Any) -> str:
    """``rater`` if it is a usable name (1-64 characters, not blank, no control characters)."""
    if not isinstance(rater, str) or not rater.strip():
        raise RequestError(
            HTTPStatus.BAD_REQUEST, f"rater must be a non-empty string, got {rater!r}"
        )
    if len(rater) > MAX_RATER_CHARS:
        raise RequestError(
            HTTPStatus.BAD_REQUEST,
            f"rater is {len(rater)} characters long; at most {MAX_RATER_CHARS} are allowed",
        )
    if any(ord(c) < 32 or ord(c) == 127 for c in rater):
        raise RequestError(HTTPStatus.BAD_REQUEST, "rater must not contain control characters")
    return rater


def parse_answer(body: bytes, study: layout.Study) -> tuple[str, str, int]:
    """(rater, pair id, answer) of a POST /api/answer body; RequestError (400) otherwise."""
    try:
        data = json.loads(body)
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise RequestError(HTTPStatus.BAD_REQUEST, f"body is not valid JSON: {err}") from None
    if not isinstance(data, dict):
        raise RequestError(
            HTTPStatus.BAD_REQUEST, 'body must be a JSON object {"rater", "pair_id", "answer"}'
        )
    missing = [f for f in ("rater", "pair_id", "answer") if f not in data]
    if missing:
        raise RequestError(
            HTTPStatus.BAD_REQUEST,
            f'missing fields {missing}; expected {{"rater", "pair_id", "answer"}}',
        )
    rater = check_rater(data["rater"])
    pair_id = data["pair_id"]
    if not isinstance(pair_id, str) or study.pair(pair_id) is None:
        raise RequestError(HTTPStatus.BAD_REQUEST, f"unknown pair_id {pair_id!r}")
    answer = data["answer"]
    if isinstance(answer, bool) or not isinstance(answer, int) or not 0 <= answer <= 4:
        raise RequestError(
            HTTPStatus.BAD_REQUEST, f"answer must be an integer 0..4, got {answer!r}"
        )
    return rater, pair_id, answer


def parse_range(header: str | None, size: int) -> tuple[int, int] | None:
    """Inclusive byte range (first, last) of a ``Range`` header over ``size`` bytes.

    None: serve the whole file (no header, or one this server does not handle, such as
    several ranges). RequestError 416 for a range outside the file.
    """
    match = _RANGE.fullmatch(header.strip()) if header else None
    if match is None or match.group(1) == match.group(2) == "":
        return None
    first, last = match.groups()
    if first == "":  # suffix: the last N bytes
        n = int(last)
        if n == 0 or size == 0:
            raise RequestError(HTTPStatus.REQUESTED_RANGE_NOT_SATISFIABLE, "empty range")
        return max(0, size - n), size - 1
    start = int(first)
    end = size - 1 if last == "" else min(int(last), size - 1)
    if start >= size or end < start:
        raise RequestError(
            HTTPStatus.REQUESTED_RANGE_NOT_SATISFIABLE, f"range outside {size} bytes"
        )
    return start, end


def render_page(study: layout.Study) -> bytes:
    """The rating page with the study's name, size and scale labels filled in."""
    template = resources.files("mjx_hands.study").joinpath("page.html").read_text()
    scale = "".join(
        f'<label for="answer-{i}"><input type="radio" name="answer" id="answer-{i}" '
        f'value="{i}">{html.escape(label)}</label>'
        for i, label in enumerate(study.scale)
    )
    fill = {"NAME": html.escape(study.name), "TOTAL": str(len(study.pairs)), "SCALE": scale}
    # One pass: a study name that spells a placeholder stays as written.
    return re.sub(r"\{\{(NAME|TOTAL|SCALE)\}\}", lambda m: fill[m.group(1)], template).encode()


class StudyServer(ThreadingHTTPServer):
    """An HTTP server of one study; answers go to its ``answers.sqlite``."""

    daemon_threads = True

    def __init__(self, study: layout.Study, address: tuple[str, int], log: bool = True) -> None:
        self.study = study
        self.store = store.AnswerStore(study.answers_path)
        self.page = render_page(study)
        self.log = log
        videos_dir = study.videos_dir.resolve()
        # Only the videos the study names, resolved once: nothing else is reachable.
        self.videos = {
            Path(getattr(p, side)).name: videos_dir / Path(getattr(p, side)).name
            for p in study.pairs
            for side in ("left", "right")
        }
        super().__init__(address, StudyHandler)

    @property
    def url(self) -> str:
        host, port = self.server_address[:2]
        return f"http://{host}:{port}/"


class StudyHandler(BaseHTTPRequestHandler):
    server: StudyServer
    protocol_version = "HTTP/1.1"
    server_version = "mjx-hands-study"
    # Browsers keep connections open; an idle one gives its thread back after this.
    timeout = 60

    # ------------------------------------------------------------- responses
    def _send(
        self,
        status: HTTPStatus,
        body: bytes,
        content_type: str,
        headers: dict[str, str] | None = None,
        head_only: bool = False,
    ) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("X-Content-Type-Options", "nosniff")
        for name, value in (headers or {}).items():
            self.send_header(name, value)
        self.end_headers()
        if not head_only:
            self.wfile.write(body)

    def _json(self, status: HTTPStatus, content: Any, head_only: bool = False) -> None:
        body = json.dumps(content).encode()
        self._send(
            status, body, "application/json", {"Cache-Control": "no-store"}, head_only=head_only
        )

    def _error(self, err: RequestError, head_only: bool = False) -> None:
        self._json(err.status, {"error": str(err)}, head_only=head_only)

    def version_string(self) -> str:
        return self.server_version  # no Python version in the Server header

    def log_message(self, format: str, *args: Any) -> None:
        if self.server.log:
            super().log_message(format, *args)

    # --------------------------------------------------------------- routes
    def do_GET(self) -> None:
        self._get(head_only=False)

    def do_HEAD(self) -> None:
        self._get(head_only=True)

    def _get(self, head_only: bool) -> None:
        url = urllib.parse.urlsplit(self.path)
        try:
            if url.path == "/":
                self._send(
                    HTTPStatus.OK,
                    self.server.page,
                    "text/html; charset=utf-8",
                    {"Cache-Control": "no-store", "Content-Security-Policy": _PAGE_POLICY},
                    head_only=head_only,
                )
            elif url.path == "/api/study":
                self._json(HTTPStatus.OK, self.server.study.public(), head_only)
            elif url.path == "/api/next":
                query = urllib.parse.parse_qs(url.query)
                self._json(HTTPStatus.OK, self._next(query.get("rater", [""])[0]), head_only)
            elif url.path.startswith("/videos/"):
                self._video(url.path.removeprefix("/videos/"), head_only)
            else:
                raise RequestError(HTTPStatus.NOT_FOUND, f"no such page: {url.path}")
        except RequestError as err:
            self._error(err, head_only)
        except (BrokenPipeError, ConnectionResetError):
            self.close_connection = True  # the browser stopped reading (seeking a video)

    def do_POST(self) -> None:
        url = urllib.parse.urlsplit(self.path)
        try:
            if url.path != "/api/answer":
                raise RequestError(HTTPStatus.NOT_FOUND, f"no such endpoint: POST {url.path}")
            rater, pair_id, answer = parse_answer(self._body(), self.server.study)
            try:
                status = self.server.store.submit(rater, pair_id, answer)
            except store.AnswerConflict as err:
                raise RequestError(HTTPStatus.CONFLICT, str(err)) from None
            self._json(HTTPStatus.OK, {"status": status})
        except RequestError as err:
            self.close_connection = True  # the body may be unread: start afresh
            self._error(err)

    def _body(self) -> bytes:
        if "chunked" in self.headers.get("Transfer-Encoding", "").lower():
            raise RequestError(HTTPStatus.LENGTH_REQUIRED, "send the body with a Content-Length")
        length = self.headers.get("Content-Length")
        if length is None or not length.strip().isdigit():
            raise RequestError(HTTPStatus.LENGTH_REQUIRED, "Content-Length header required")
        if int(length) > MAX_BODY_BYTES:
            raise RequestError(
                HTTPStatus.REQUEST_ENTITY_TOO_LARGE,
                f"body of {int(length)} bytes; at most {MAX_BODY_BYTES} are accepted",
            )
        body = self.rfile.read(int(length))
        content_type = self.headers.get("Content-Type", "").split(";")[0].strip().lower()
        # Requiring JSON makes a cross-site form post impossible without a CORS preflight.
        if content_type != "application/json":
            raise RequestError(
                HTTPStatus.UNSUPPORTED_MEDIA_TYPE,
                f"Content-Type must be application/json, got {content_type or 'none'!r}",
            )
        return body

    def _next(self, rater: str) -> dict[str, Any]:
        rater = check_rater(rater)
        study = self.server.study
        answered = self.server.store.answered(rater) & {p.id for p in study.pairs}
        total = len(study.pairs)
        for pid in rater_order(rater, [p.id for p in study.pairs]):
            if pid not in answered:
                pair = study.pair(pid)
                assert pair is not None
                public = pair.public()
                return {"done": False, "pair": public, "answered": len(answered), "total": total}
        return {"done": True, "answered": total, "total": total}

    def _video(self, quoted_name: str, head_only: bool) -> None:
        name = urllib.parse.unquote(quoted_name)
        path = self.server.videos.get(name)
        # Resolving again catches a link swapped in after start that leads elsewhere.
        if path is None or not path.is_file() or path.resolve().parent != path.parent:
            raise RequestError(HTTPStatus.NOT_FOUND, f"no such video: {quoted_name}")
        size = path.stat().st_size
        content_type = mimetypes.guess_type(name)[0] or "application/octet-stream"
        span = parse_range(self.headers.get("Range"), size)
        first, last = span if span is not None else (0, size - 1)
        length = last - first + 1 if size else 0
        status = HTTPStatus.PARTIAL_CONTENT if span is not None else HTTPStatus.OK
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(length))
        self.send_header("Accept-Ranges", "bytes")
        self.send_header("X-Content-Type-Options", "nosniff")
        if span is not None:
            self.send_header("Content-Range", f"bytes {first}-{last}/{size}")
        self.end_headers()
        if head_only:
            return
        with path.open("rb") as f:
            f.seek(first)
            remaining = length
            while remaining > 0:
                chunk = f.read(min(_CHUNK, remaining))
                if not chunk:
                    break
                self.wfile.write(chunk)
                remaining -= len(chunk)

    def send_error(self, code: int, message: str | None = None, explain: str | None = None) -> None:
        # Protocol errors (bad request line, unsupported method) as JSON like the API's.
        self.close_connection = True
        try:
            self._json(HTTPStatus(code), {"error": message or HTTPStatus(code).phrase})
        except (BrokenPipeError, ConnectionResetError):
            pass


def make_server(
    study_dir: str | os.PathLike[str], host: str = "127.0.0.1", port: int = 8000, log: bool = True
) -> StudyServer:
    """A bound, not yet serving, server of the study in ``study_dir`` (port 0: a free one)."""
    study = layout.read_study(study_dir)
    return StudyServer(study, (host, port), log=log)


def serve(study_dir: str | os.PathLike[str], host: str = "127.0.0.1", port: int = 8000) -> None:
    """Serve the study until interrupted; prints the page's URL first."""
    server = make_server(study_dir, host, port)
    study = server.study
    print(
        f"study {study.name!r}: {len(study.pairs)} pairs, answers in {study.answers_path}",
        flush=True,
    )
    print(f"serving at {server.url}", flush=True)
    if host == "0.0.0.0":
        port = server.server_address[1]
        print(
            f"listening on every interface: raters open http://<this machine>:{port}/", flush=True
        )
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        print("stopped", file=sys.stderr)
    finally:
        server.server_close()

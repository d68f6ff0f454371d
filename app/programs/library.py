"""The program library: every program sent to be checked, dry-run or run, kept so that an
operator can reopen it (from any browser: it lives on the server, under the runs folder).

A program is kept by its text: its id is the first 16 hex digits of the SHA-256 of its
UTF-8 bytes, so the same text sent again is one entry (its name, work offset, last action
and time updated, its count of sends raised). Each entry is two files in the library's
folder (``<runs folder>/programs/``): ``<id>.ngc`` (the text) and ``<id>.json`` (name,
bytes, lines, first line, sent_at, action, sends, work_offset_m). Files are named only by
the id the library makes (16 lowercase hex digits), never by a name a client gives: a name
is a label in the JSON, and an id is checked against that form before any path is made,
so no request reaches a file outside the folder.

Caps: a program over MAX_BYTES is not kept (``add`` returns None: the check goes on); at
most MAX_ENTRIES are kept, the least recently sent removed first. Writes are atomic (a
temporary file renamed) and serialised in this process by a lock.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Literal

MAX_BYTES = 2 * 1024 * 1024  # [bytes] a program longer is not kept (100,000 lines is ~2 MB)
MAX_ENTRIES = 200  # the least recently sent beyond are removed
MAX_NAME = 120  # [characters] of a program's name
ID_RE = re.compile(r"^[0-9a-f]{16}$")
ACTIONS = ("check", "dry-run", "run")
_LOCK = threading.Lock()

Action = Literal["check", "dry-run", "run"]


class LibraryError(ValueError):
    """A library request refused: ``field`` names the input at fault, the message the
    reason (``field: reason``)."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


@dataclass(frozen=True)
class Entry:
    """A kept program: id (16 hex digits), name (the label it was sent with), bytes (its
    UTF-8 size), lines, first (its first non-empty line, up to 80 characters), sent_at
    (the last send, seconds since the epoch, UTC), action (the last: check, dry-run or
    run), sends (how many times it was sent), work_offset_m (the G54 origin it was last
    sent with [m]; None: the config's)."""

    id: str
    name: str
    bytes: int
    lines: int
    first: str
    sent_at: float
    action: str
    sends: int
    work_offset_m: list[float] | None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def program_id(text: str) -> str:
    """The library id of ``text``: the first 16 hex digits of its UTF-8 SHA-256."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def check_name(name: str) -> str:
    """``name`` stripped, or LibraryError (field ``name``): empty, over MAX_NAME characters,
    with a control character, or with a path separator (a name is a label, not a path)."""
    name = name.strip()
    if not name:
        raise LibraryError("name", "empty: give the program a name (its file's, or 'unsaved')")
    if len(name) > MAX_NAME:
        raise LibraryError("name", f"{len(name)} characters, over the {MAX_NAME} allowed")
    if any(ord(c) < 32 or ord(c) == 127 for c in name):
        raise LibraryError("name", "has a control character (a tab, a newline, ...)")
    if "/" in name or "\\" in name:
        raise LibraryError("name", "has a '/' or '\\': a name is a label, not a path")
    return name


def check_id(program: str) -> str:
    """``program`` if it is an id of the library's form (16 lowercase hex digits), else
    LibraryError (field ``id``): no other string ever becomes a path."""
    if not ID_RE.fullmatch(program):
        raise LibraryError("id", "not a program id (16 hex digits, from the library's list)")
    return program


def _first_line(text: str) -> str:
    for line in text.splitlines():
        if line.strip():
            return line.strip()[:80]
    return ""


def _write(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


class ProgramLibrary:
    """The programs kept in ``folder`` (created on the first add)."""

    def __init__(
        self, folder: Path, max_bytes: int = MAX_BYTES, max_entries: int = MAX_ENTRIES
    ) -> None:
        self.folder = Path(folder)
        self.max_bytes = max_bytes
        self.max_entries = max_entries

    def add(
        self,
        text: str,
        name: str,
        action: Action,
        work_offset_m: list[float] | tuple[float, ...] | None = None,
        now: float | None = None,
    ) -> Entry | None:
        """Keep ``text`` as ``name`` (sent for ``action`` at ``now``, default the clock [s]);
        the entry, or None for a text over ``max_bytes`` (not kept). LibraryError for a bad
        name or action; OSError when the folder cannot be written."""
        name = check_name(name)
        if action not in ACTIONS:
            raise LibraryError("action", f"{action!r} is not one of {', '.join(ACTIONS)}")
        data = text.encode("utf-8")
        if len(data) > self.max_bytes:
            return None
        ident = program_id(text)
        with _LOCK:
            self.folder.mkdir(parents=True, exist_ok=True)
            old = self._entry(ident)
            entry = Entry(
                id=ident,
                name=name,
                bytes=len(data),
                lines=len(text.splitlines()),
                first=_first_line(text),
                sent_at=time.time() if now is None else float(now),
                action=action,
                sends=(old.sends if old else 0) + 1,
                work_offset_m=None if work_offset_m is None else [float(v) for v in work_offset_m],
            )
            if old is None:
                _write(self.folder / f"{ident}.ngc", data)
            _write(self.folder / f"{ident}.json", json.dumps(entry.to_dict()).encode())
            self._prune()
        return entry

    def entries(self) -> list[Entry]:
        """The kept programs, the most recently sent first."""
        if not self.folder.is_dir():
            return []
        out = []
        for path in self.folder.glob("*.json"):
            if ID_RE.fullmatch(path.stem) and (entry := self._entry(path.stem)) is not None:
                out.append(entry)
        return sorted(out, key=lambda e: (-e.sent_at, e.id))

    def get(self, program: str) -> tuple[Entry, str]:
        """The entry and text of id ``program``: LibraryError (field ``id``) for a string not
        of the id's form; KeyError when no such program is kept."""
        ident = check_id(program)
        entry = self._entry(ident)
        text_path = self.folder / f"{ident}.ngc"
        if entry is None or not text_path.is_file():
            raise KeyError(ident)
        return entry, text_path.read_bytes().decode("utf-8")

    def _entry(self, ident: str) -> Entry | None:
        try:
            data = json.loads((self.folder / f"{ident}.json").read_text())
            return Entry(**data)
        except (OSError, ValueError, TypeError):  # absent, half-written by hand, foreign
            return None

    def _prune(self) -> None:
        for entry in self.entries()[self.max_entries :]:
            for suffix in (".json", ".ngc"):
                (self.folder / f"{entry.id}{suffix}").unlink(missing_ok=True)

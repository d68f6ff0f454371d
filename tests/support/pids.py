"""A worker process says its pid to a test through a file."""

from __future__ import annotations

import os
from pathlib import Path


def say_pid(path: str | Path) -> None:
    """Write this process's pid to ``path`` whole, then rename it into place.

    The test polls for the file and reads the pid at once: a plain ``write_text`` lets it
    read a file created but not yet written (CI read ``''``).
    """
    said = Path(path)
    partial = said.with_name(said.name + ".partial")
    partial.write_text(str(os.getpid()))
    partial.replace(said)

"""The scene's saved goal points on disk, so they outlive a restart of the server.

One JSON file, `{"points": {"name": [x, y, z], ...}}` in metres, base frame, written to a
temporary file and renamed over the old one (a crash never leaves half a file). A file
that cannot be read, or an entry that is not three finite numbers, is skipped with a
warning naming it: the scene starts with what is good, never fails to start.
"""

from __future__ import annotations

import json
import logging
import math
import os
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)
FILE_NAME = "goal_points.json"


def load_points(path: Path) -> dict[str, np.ndarray]:
    """The saved points in ``path`` (name -> (3,) [m]); empty if there is no file yet."""
    if not path.exists():
        return {}
    try:
        entries = json.loads(path.read_text(encoding="utf-8"))["points"]
        items = list(entries.items())
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        log.warning("goal points: cannot read %s (%s); starting with none", path, exc)
        return {}
    points: dict[str, np.ndarray] = {}
    for name, value in items:
        if not _is_point(value):
            log.warning("goal points: %s: %r is not three finite numbers; skipped", name, value)
            continue
        points[str(name)] = np.array(value, dtype=np.float64)
    return points


def save_points(path: Path, points: dict[str, np.ndarray]) -> None:
    """Write ``points`` to ``path`` atomically (the folder is created)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    body = {"points": {name: [float(v) for v in point] for name, point in points.items()}}
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(json.dumps(body, indent=1), encoding="utf-8")
    os.replace(temporary, path)


def _is_point(value: object) -> bool:
    if not isinstance(value, list) or len(value) != 3:
        return False
    return all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value
    )

"""The deliberate breaks of benchmarks/breaks/ stay usable (issue 29 §2): the manifest lists
every patch once, each touches only product code, and each applies cleanly to HEAD.

Which tests catch each break is benchmarks/breaks.py's to measure (minutes); this only
keeps the patches from rotting silently as the code they break moves on.
"""

from __future__ import annotations

import importlib.util
import shutil
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "benchmarks" / "breaks.py"


def _breaks():
    """benchmarks/breaks.py as a module (registered first: its dataclasses look it up)."""
    name = "deltadash_breaks_script"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, SCRIPT)
        assert spec is not None and spec.loader is not None
        sys.modules[name] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(sys.modules[name])
    return sys.modules[name]


@pytest.mark.skipif(
    shutil.which("git") is None or not (ROOT / ".git").exists(), reason="not a git checkout"
)
def test_every_break_is_listed_once_and_applies_to_head() -> None:
    breaks = _breaks()
    items = breaks.load()
    assert len(items) >= 20
    assert len({b.id for b in items}) == len(items) == len(list(breaks.BREAKS.glob("*.patch")))
    assert all(b.tests and b.what and b.layer for b in items)
    breaks.check(items)  # raises ManifestError naming a patch that does not apply

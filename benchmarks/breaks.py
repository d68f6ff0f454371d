"""Deliberate breaks of the product, and which tests catch each (issue 29 §2).

Usage: python benchmarks/breaks.py [--only 03,07] [--full | --tests SEL ...] [--python PY]
                                   [--markdown FILE] [--keep] [--check]

Each patch in benchmarks/breaks/ (NN-short-name.patch, listed in manifest.toml with its
layer, what it breaks and the tests that should catch it) is a small, plausible bug in the
product code (kinematics/, hardware/, app/, static/). For each break this script:

1. makes a pristine copy of the tree at HEAD (``git archive HEAD``; uncommitted changes are
   not in it) in a temporary folder;
2. applies the patch there with ``git apply`` (a patch that does not apply fails loudly);
3. runs ``PY -m pytest -q -p no:cacheprovider SELECTION --junitxml=...`` from inside the
   copy, where SELECTION is the manifest's ``tests`` (``--full``: the whole suite,
   ``tests -m "not browser"``; a break only browser tests can catch, ``browser = true``,
   runs its selection instead; ``--tests`` replaces every break's selection, to look for
   a catching test in a wider net);
4. reads the failing and erroring test ids from the junit XML.

It prints a table (id, layer, what, caught, how many tests caught it, the first few) and
with ``--markdown FILE`` writes it as Markdown. The exit status is 1 if any break was not
caught (no failing test), 2 if a patch does not apply or the manifest is inconsistent.
A pytest killed by a signal (the shared machine's other work can end it) is run once more;
the note says so.

``--check`` only verifies that the manifest lists every patch once and that each applies
cleanly to the working tree (a second or so; tests/test_breaks.py runs it), so patches do not rot as
the code moves on: a patch that no longer applies is rewritten against the new code, and
a break the suite no longer catches is a finding, not a patch to drop.

The copy imports its own packages: ``python -m pytest`` puts the copy first on sys.path,
PYTHONPATH names it for the servers the tests start, and a ``deltadash_static`` link to
its static/ wins over an editable install's mapping of the dashboard to another checkout.
Times are wall-clock seconds per break (pytest's collection and start included).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BREAKS = ROOT / "benchmarks" / "breaks"
MANIFEST = BREAKS / "manifest.toml"
PRODUCT = ("kinematics/", "hardware/", "app/", "static/")
SHOWN = 3  # catching tests named in the table


@dataclass(frozen=True)
class Break:
    """One manifest entry and its patch file."""

    id: str
    layer: str
    what: str
    tests: tuple[str, ...]
    patch: Path
    browser: bool = False


@dataclass
class Outcome:
    """What one break's run found: the failing/erroring test ids, pytest's exit status
    and the run's wall-clock time [s]."""

    item: Break
    caught_by: list[str] = field(default_factory=list)
    returncode: int = 0
    seconds: float = 0.0
    note: str = ""

    @property
    def caught(self) -> bool:
        return bool(self.caught_by)


class ManifestError(Exception):
    """The manifest and the patch files do not match, or a patch does not apply."""


def load(manifest: Path = MANIFEST) -> list[Break]:
    """The manifest's breaks in id order, each matched to exactly one patch file.

    Raises ManifestError for a patch not listed, an id listed twice or without a patch, a
    missing field, or a patch that touches files outside the product code.
    """
    entries = tomllib.loads(manifest.read_text())["break"]
    patches = {p.name[:2]: p for p in sorted(manifest.parent.glob("*.patch"))}
    names = [p.name for p in manifest.parent.glob("*.patch")]
    if len(patches) != len(names):
        raise ManifestError(f"two patches share a number: {sorted(names)}")
    breaks, seen = [], set()
    for entry in entries:
        missing = {"id", "layer", "what", "tests"} - entry.keys()
        if missing:
            raise ManifestError(f"break {entry.get('id')!r}: missing {sorted(missing)}")
        bid = entry["id"]
        if bid in seen:
            raise ManifestError(f"break {bid} is listed twice")
        seen.add(bid)
        if bid not in patches:
            raise ManifestError(f"break {bid}: no {bid}-*.patch in {manifest.parent}")
        if not entry["tests"]:
            raise ManifestError(f"break {bid}: no tests to run")
        patch = patches[bid]
        touched = _touched(patch)
        outside = [t for t in touched if not t.startswith(PRODUCT)]
        if not touched or outside:
            raise ManifestError(f"{patch.name}: touches {outside or 'nothing'}, not product code")
        breaks.append(
            Break(
                bid,
                entry["layer"],
                entry["what"],
                tuple(entry["tests"]),
                patch,
                bool(entry.get("browser", False)),
            )
        )
    unlisted = sorted(set(patches) - seen)
    if unlisted:
        raise ManifestError(f"patches not in the manifest: {[patches[i].name for i in unlisted]}")
    return sorted(breaks, key=lambda b: b.id)


def _touched(patch: Path) -> list[str]:
    """Files a unified diff changes (its ``+++ b/...`` lines)."""
    lines = patch.read_text().splitlines()
    return [line[6:] for line in lines if line.startswith("+++ b/")]


def pristine_copy(folder: Path) -> None:
    """The tree at HEAD in ``folder`` (empty or new), with the dashboard's package link."""
    folder.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(
        ["git", "-C", str(ROOT), "archive", "HEAD"], check=True, capture_output=True
    ).stdout
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    (folder / "deltadash_static").symlink_to("static", target_is_directory=True)


def apply(patch: Path, folder: Path, check_only: bool = False) -> None:
    """``git apply`` the patch in ``folder``; ManifestError (with git's words) if it fails."""
    command = ["git", "apply", "--check" if check_only else "--whitespace=nowarn", str(patch)]
    done = subprocess.run(command, cwd=folder, capture_output=True, text=True)
    if done.returncode != 0:
        raise ManifestError(f"{patch.name} does not apply in {folder}: {done.stderr.strip()}")


def check(breaks: list[Break], folder: Path = ROOT) -> None:
    """Every patch applies cleanly (each on its own) to the tree in ``folder``: this
    checkout's working tree by default, which ``git apply --check`` leaves as it is."""
    for item in breaks:
        apply(item.patch, folder, check_only=True)


def failing_tests(junit: Path) -> list[str]:
    """Node-like ids (``file::Class::name``) of the failed and errored test cases."""
    if not junit.exists():
        return []
    found = []
    for case in ET.parse(junit).getroot().iter("testcase"):
        if case.find("failure") is None and case.find("error") is None:
            continue
        parts = (case.get("classname") or "").split(".")  # tests.a.test_b[.Class]
        modules = [p for p in parts if p and not p[:1].isupper()]
        classes = [p for p in parts if p[:1].isupper()]
        path = "/".join(modules) + ".py" if modules else ""
        found.append("::".join([x for x in (path, *classes) if x] + [case.get("name", "")]))
    return found


def run_one(
    item: Break, python: str, full: bool, keep: bool, tests: list[str] | None = None
) -> Outcome:
    """Apply one break to a pristine copy and run its selection; the failing tests."""
    outcome = Outcome(item)
    tmp = Path(tempfile.mkdtemp(prefix=f"deltadash-break-{item.id}-"))
    try:
        folder = tmp / "tree"
        pristine_copy(folder)
        apply(item.patch, folder)
        junit = tmp / "junit.xml"
        selection = list(item.tests) if (item.browser or not full) else ["tests"]
        marker = ["-m", "not browser"] if full and not item.browser else []
        if tests:
            selection, marker = list(tests), []
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(folder), *_pythonpath()])}
        command = [python, "-m", "pytest", "-q", "-p", "no:cacheprovider", *marker]
        command += [*selection, f"--junitxml={junit}"]
        started = time.monotonic()
        done = subprocess.run(command, cwd=folder, env=env, capture_output=True, text=True)
        if done.returncode < 0:  # killed by a signal: not an answer; once more
            outcome.note = f"rerun after signal {-done.returncode}"
            junit.unlink(missing_ok=True)
            started = time.monotonic()
            done = subprocess.run(command, cwd=folder, env=env, capture_output=True, text=True)
        outcome.seconds = time.monotonic() - started
        outcome.returncode = done.returncode
        outcome.caught_by = failing_tests(junit)
        if done.returncode not in (0, 1):  # 2-5: interrupted, internal error, usage, none
            tail = (done.stdout + done.stderr).strip().splitlines()[-3:]
            outcome.note += f" pytest exit {done.returncode}: {' / '.join(tail)}"
        if keep:
            (tmp / "pytest.log").write_text(done.stdout + done.stderr)
            outcome.note = (outcome.note + f" kept {tmp}").strip()
    finally:
        if not keep:
            subprocess.run(["rm", "-rf", str(tmp)], check=False)
    return outcome


def _pythonpath() -> list[str]:
    value = os.environ.get("PYTHONPATH", "")
    return [p for p in value.split(os.pathsep) if p]


def table(outcomes: list[Outcome]) -> str:
    """The results as a Markdown table."""
    rows = [
        "| id | layer | what | caught | tests failing | first catching tests | s |",
        "|---|---|---|---|---|---|---|",
    ]
    for o in outcomes:
        shown = ", ".join(f"`{t}`" for t in o.caught_by[:SHOWN])
        if len(o.caught_by) > SHOWN:
            shown += ", ..."
        caught = "yes" if o.caught else "**NO**"
        note = f" ({o.note})" if o.note and not o.caught else ""
        what = o.item.what.replace("|", "\\|")
        rows.append(
            f"| {o.item.id} | {o.item.layer} | {what} | {caught} | {len(o.caught_by)} | "
            f"{shown or '-'}{note} | {o.seconds:.0f} |"
        )
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", help="comma-separated ids, e.g. 03,07")
    parser.add_argument("--full", action="store_true", help='whole suite (-m "not browser")')
    parser.add_argument("--tests", nargs="+", help="run these tests for every break instead")
    parser.add_argument("--python", default=sys.executable, help="interpreter to run pytest")
    parser.add_argument("--markdown", type=Path, help="write the table to this file")
    parser.add_argument("--keep", action="store_true", help="keep each copy and pytest's log")
    parser.add_argument("--check", action="store_true", help="only check the patches apply")
    args = parser.parse_args(argv)
    try:
        breaks = load()
        if args.only:
            wanted = {i.strip().zfill(2) for i in args.only.split(",") if i.strip()}
            unknown = wanted - {b.id for b in breaks}
            if unknown:
                raise ManifestError(f"no such breaks: {sorted(unknown)}")
            breaks = [b for b in breaks if b.id in wanted]
        if args.check:
            check(breaks)
            print(f"{len(breaks)} patches listed once, each applying cleanly to the tree")
            return 0
        outcomes = []
        started = time.monotonic()
        for item in breaks:
            outcome = run_one(item, args.python, args.full, args.keep, args.tests)
            outcomes.append(outcome)
            mark = "caught" if outcome.caught else "NOT CAUGHT"
            first = ", ".join(outcome.caught_by[:SHOWN])
            print(
                f"{item.id} {item.layer:11} {mark} by {len(outcome.caught_by)} "
                f"({outcome.seconds:.0f} s) {first} {outcome.note}",
                flush=True,
            )
    except ManifestError as exc:
        print(f"breaks: {exc}", file=sys.stderr)
        return 2
    text = table(outcomes)
    total = time.monotonic() - started
    print()
    print(text)
    print(f"{sum(o.caught for o in outcomes)} of {len(outcomes)} caught in {total:.0f} s")
    if args.markdown:
        args.markdown.write_text(text)
    return 0 if all(o.caught for o in outcomes) else 1


if __name__ == "__main__":
    sys.exit(main())

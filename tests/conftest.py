"""Shared test settings: hypothesis profiles sized for a 2-core CI machine."""

import os

import pytest
from hypothesis import HealthCheck, settings

# CI replays the same examples every run (derandomize): a red CI is a real, reproducible
# failure; exploring new examples is the "soak" profile's job, run by hand.
settings.register_profile(
    "ci",
    max_examples=150,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile("dev", max_examples=60, deadline=None)
settings.register_profile("soak", max_examples=3000, deadline=None)  # by hand, before a release
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci" if os.environ.get("CI") else "dev"))


def pytest_unconfigure(config):  # pragma: no cover - diagnostics
    """Say which threads outlive the session, and where they are: a daemon thread inside
    native code when the interpreter finalizes crashes the process after every test passed
    (CI saw "terminate called without an active exception")."""
    import sys
    import threading
    import traceback

    alive = [t for t in threading.enumerate() if t is not threading.main_thread()]
    frames = sys._current_frames()
    for thread in alive:
        where = traceback.format_stack(frames[thread.ident])[-2:] if thread.ident in frames else []
        print(f"\nthread alive at exit: {thread.name}\n{''.join(where)}", file=sys.stderr)


# Where real time is the point (a real chromium, the emulator's replies on a pty in wall
# time), tests run one after another in one worker: chromium's software WebGL can take both
# cores for seconds, and an emulator thread descheduled that long misses its replies.
REAL_TIME_GROUP = "real-time"
REAL_TIME_FOLDERS = ("tests/hardware/dynamixel/", "tests/hardware/emulator/")


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook reads the groups
def pytest_collection_modifyitems(config, items):
    """With ``--dist loadgroup`` (make test, make test-fast): each module is a group (its
    fixtures stay in one worker, as ``loadfile``), except that every real-time test (the
    comment above) is in one group of its own. (pytest 9.2 broke xdist's groups,
    pytest-dev/pytest-xdist#1386: pyproject.toml keeps pytest below it.)"""
    for item in items:
        if item.get_closest_marker("xdist_group"):
            continue
        path = item.nodeid.split("::")[0]
        real_time = item.get_closest_marker("browser") or path.startswith(REAL_TIME_FOLDERS)
        item.add_marker(pytest.mark.xdist_group(REAL_TIME_GROUP if real_time else path))

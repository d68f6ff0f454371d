"""Shared test settings: hypothesis profiles sized for a 2-core CI machine."""

import os

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

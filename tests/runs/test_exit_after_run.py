"""A server that stops right after a run ends still writes the run's report, and its
process exits cleanly: the report is drawn (matplotlib, native code) in the recorder's
daemon thread, and a process that exited meanwhile crashed in finalization ("terminate
called without an active exception", after every test in CI had passed)."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

SCRIPT = textwrap.dedent(
    """
    import sys, tempfile
    from pathlib import Path
    from tests.support.app_client import make_client, settle_at
    from tests.support.lease import take_lease
    from tests.support.wait import ok_json, wait_for

    if __name__ == "__main__":
        folder = Path(tempfile.mkdtemp())
        patient = {"stale_feedback_s": 5.0, "following_error_time_s": 5.0}
        with make_client(folder, backend="sim", safety=patient) as client:
            take_lease(client)
            settle_at(client, [0.0, 0.0, -0.24])
            run = ok_json(client.post("/api/tests/sinusoid", json={"duration_s": 0.5}))
            run_id = run["run_id"]
            wait_for(
                lambda: ok_json(client.get(f"/api/runs/{run_id}"))["state"] != "running",
                "the run to end",
            )
        # the server has stopped: the report must be there, however late it was drawn
        print("report", any(folder.glob(f"**/{run_id}*/report.png")))
    """
)


@pytest.mark.slow  # a server on the twin in a subprocess
def test_a_server_stopped_as_a_run_ends_writes_its_report_and_exits_cleanly(tmp_path):
    script = tmp_path / "stop_after_run.py"
    script.write_text(SCRIPT)
    root = Path(__file__).resolve().parents[2]  # the repository: ``tests`` imports
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]),
    }
    done = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=300, env=env
    )
    assert done.returncode == 0, f"exit status {done.returncode}: {done.stderr[-3000:]}"
    assert "report True" in done.stdout, done.stdout + done.stderr[-3000:]

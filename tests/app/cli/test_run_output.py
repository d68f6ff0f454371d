"""What `deltadash run` prints about a finished run: its loop health in one line."""

from __future__ import annotations

from app.cli.run import print_stats


def _run(health: dict | None) -> dict:
    stats = {} if health is None else {"health": health}
    return {
        "run_id": "r1",
        "kind": "step",
        "params": {},
        "conditions": {},
        "state": "done",
        "reason": None,
        "stats": stats,
        "files": {},
    }


def test_a_healthy_run_says_so_and_an_unhealthy_one_says_why(capsys):
    print_stats(_run({"ok": True, "reasons": []}))
    assert "loop health: OK" in capsys.readouterr().out.splitlines()
    reasons = ["the loop paused 318 ms between two ticks (limit 20 ms)", "stale feedback: x"]
    print_stats(_run({"ok": False, "reasons": reasons}))
    assert (
        "loop health: NOT OK — the loop paused 318 ms between two ticks (limit 20 ms); "
        "stale feedback: x"
    ) in capsys.readouterr().out.splitlines()


def test_a_run_without_stats_prints_no_health_line(capsys):
    print_stats(_run(None))
    assert "loop health" not in capsys.readouterr().out

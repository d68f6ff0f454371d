"""The page when its robot node goes away: a station (`deltadash serve --robot`) whose
robot node (`deltadash robot`) is killed says "robot offline" in its banner, not that the
server is gone, and the banner goes once a node answers on that endpoint again."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.support.browser import PAGE_WAIT_S, browser_skip_reason, dashboard_page
from tests.support.robot_node import robot_node
from tests.support.server import serve, wait_for

SKIP = browser_skip_reason()
pytestmark = [
    pytest.mark.browser,
    pytest.mark.slow,
    pytest.mark.skipif(SKIP is not None, reason=str(SKIP)),
]


def _banner(page) -> str | None:
    shown = page.evaluate(
        "(() => { const b = document.getElementById('banner');"
        # a page still loading on a busy machine has no banner yet: not connected either
        " if (!b) return 'the page is loading';"
        " return b.hidden ? null : b.textContent; })()"
    )
    return shown


def test_a_lost_robot_node_is_named_in_the_banner_and_its_return_clears_it(
    tmp_path: Path,
) -> None:
    with (
        robot_node(tmp_path) as node,
        serve(tmp_path, DELTADASH_LINK__ROBOT=node.endpoint) as server,
        dashboard_page(server) as page,
    ):
        wait_for(lambda: _banner(page) is None, "the page connected", PAGE_WAIT_S)
        node.kill()
        node.process.wait()
        said = wait_for(
            lambda: (shown := _banner(page)) and shown.startswith("Robot offline") and shown,
            "the page's banner naming the robot",
            PAGE_WAIT_S,
            seen=lambda: _banner(page),
        )
        assert "the server is" not in said.lower()  # the server answers: it says why
        assert page.text_content("#conn") == "robot offline"
        with robot_node(tmp_path, endpoint=node.endpoint):
            wait_for(lambda: _banner(page) is None, "the banner gone", PAGE_WAIT_S)

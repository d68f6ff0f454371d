"""A server reachable from other machines (0.0.0.0) with a token: the page reads nothing
without it, asks for it once, then shows status, streams and commands with the lease."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tests.support.browser import browser_skip_reason, chromium_page, plots_frame
from tests.support.server import Server, serve, wait_for

SKIP = browser_skip_reason()
pytestmark = [pytest.mark.browser, pytest.mark.skipif(SKIP is not None, reason=str(SKIP))]
TOKEN = "networked-page-token"


@pytest.fixture(scope="module")
def networked(tmp_path_factory) -> Iterator[Server]:
    folder = tmp_path_factory.mktemp("dashboard-networked")
    env = {
        "DELTADASH_SERVER__TOKEN": TOKEN,
        "DELTADASH_SERVER__HOST": "0.0.0.0",
        "DELTADASH_SERVER__SCENE": "false",
    }
    with serve(folder, **env) as server:
        yield server


def test_the_page_asks_for_the_token_once_then_reads_and_commands(networked: Server) -> None:
    prompts: list[str] = []

    def answer(dialog: Any) -> None:
        prompts.append(dialog.message)
        dialog.accept(TOKEN)

    with chromium_page(1280, 800) as page:
        page.on("dialog", answer)
        page.goto(networked.url + "/")
        wait_for(lambda: page.locator("#servo-rows tr").count() == 3, "status read with the token")
        plots = plots_frame(page)  # the plots' frame: its stream was refused, the page asked
        wait_for(lambda: plots.evaluate("window.deltadashPlot.connected"), "telemetry with token")
        page.click("#torque-on")  # the first click asks for the token (once)
        wait_for(  # then clicked until accepted (an arm past its joint limits is refused)
            lambda: (
                page.evaluate("""fetch('/api/status', {headers: {Authorization:
                 'Bearer ' + sessionStorage.getItem('deltadash.token')}}).then(r => r.json())
                 .then(s => s.torque)""")
                or page.click("#torque-on")
            ),
            "torque on from the page",
        )
        assert len(prompts) == 1, prompts

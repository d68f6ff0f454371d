"""/docs and /redoc load their scripts and styles from the server itself, never a CDN."""

from __future__ import annotations

import re

import pytest
from fastapi.testclient import TestClient

from app.config import load_settings
from app.server import create_app
from tests.support.app_client import LocalClient

ASSET = re.compile(r"""(?:src|href)=["']([^"']+)["']""")


@pytest.fixture(scope="module")
def client() -> TestClient:
    # No `with`: the lifespan (bus, loop, scene) is not needed to serve the documentation.
    return LocalClient(create_app(load_settings()))


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_docs_pages_reference_only_local_assets(client: TestClient, page: str) -> None:
    response = client.get(page)
    assert response.status_code == 200
    html = response.text
    assert "http://" not in html and "https://" not in html, f"{page} names an external URL"
    assets = ASSET.findall(html)
    assert any(a.endswith(".js") for a in assets), f"{page} loads no script: {assets}"
    for asset in assets:
        assert asset.startswith("/") and not asset.startswith("//"), f"{page}: {asset}"
        fetched = client.get(asset)
        assert fetched.status_code == 200 and fetched.content, f"{page}: {asset} not served"


@pytest.mark.slow
def test_the_openapi_document_the_docs_read_is_served(client: TestClient) -> None:
    assert client.get("/openapi.json").json()["info"]["title"] == "deltadash"

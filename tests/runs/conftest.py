"""The runs' API tests use the server tests' running app on the emulated bus."""

from tests.app.server.conftest import client, fresh  # noqa: F401

"""The HTTP server: the FastAPI app, its lifespan, the backends it opens, its routers.

``create_app`` is imported on first use (PEP 562), so that a process that needs one of
the server's light modules (a workspace query's worker imports app.server.sections)
does not pay for FastAPI, the scene and the twin.
"""

from typing import Any

__all__ = ["create_app"]


def __getattr__(name: str) -> Any:
    if name == "create_app":
        from app.server.app import create_app

        return create_app
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

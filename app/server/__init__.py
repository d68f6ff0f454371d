"""The HTTP server: the FastAPI app, its lifespan, the backends it opens, its routers."""

from app.server.app import create_app

__all__ = ["create_app"]

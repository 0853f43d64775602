"""The web service: REST renders, the WebSocket walk-through and the browser client (``create_app``)."""

from .app import create_app

__all__ = ["create_app"]

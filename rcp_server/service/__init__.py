"""The web service: REST renders, the WebSocket walk-through and the browser client (``app.create_app``)."""

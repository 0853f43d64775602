"""The styles (``GET /api/styles``): the named looks a ``paint`` may ask for by ``"style"``."""

from __future__ import annotations

from dataclasses import asdict

from fastapi import APIRouter

from ...settings.styles import STYLES
from .. import protocol

router = APIRouter(prefix="/api")


@router.get("/styles")
async def styles() -> list[protocol.StyleInfo]:
    """Every style with its settings, in the order a picker lists them."""
    return [protocol.StyleInfo(**asdict(style)) for style in STYLES.values()]

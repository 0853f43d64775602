"""Service settings, in one place, read from ``RCP_*`` environment variables (``RCP_PORT=9000``)."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

from ..painting import default_threads
from ..scenefile import SCENES_DIR

CLIENT_DIR = Path(__file__).resolve().parent.parent.parent / "client"


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="RCP_")

    host: str = "127.0.0.1"
    port: int = Field(8000, ge=0, le=65535)
    scenes: Path = SCENES_DIR  # the folder scene names resolve in
    client: Path = CLIENT_DIR  # the browser client's static files
    threads: int = Field(default_factory=default_threads, ge=1, le=256)  # tile workers shared by all renders
    max_renders: int = Field(4, ge=1)  # paintings in progress at once; more wait their turn
    max_sessions: int = Field(8, ge=1)  # WebSocket walk-throughs at once
    max_pixels: int = Field(4096 * 2160, ge=1)  # width x height of one image
    frame_ms: float = Field(60.0, gt=0)  # while walking, aim for frames at least this fast
    settle_ms: float = Field(150.0, ge=0)  # the camera is at rest after this long without a message

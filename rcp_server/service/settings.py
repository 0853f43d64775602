"""Service settings, in one place, read from ``RCP_*`` environment variables (``RCP_PORT=9000``).

Every limit a caller can run into is here, with a default that keeps one 2-core machine serving everyone.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from ..painting.loop import default_threads
from ..scene.untrusted import Limits
from ..settings.params import PaintParams

REPOSITORY = Path(__file__).resolve().parent.parent.parent
CLIENT_DIR = REPOSITORY / "client"
BUNDLED_SCENES = REPOSITORY / "scenes"  # RCP_SCENES names another folder: the service reads it once, below


def default_data() -> Path:
    """The user's data directory (XDG): ``$XDG_DATA_HOME/rcp``, else ``~/.local/share/rcp``."""
    return Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share") / "rcp"


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="RCP_")

    host: str = "127.0.0.1"  # loopback only unless asked: the container sets 0.0.0.0
    port: int = Field(8000, ge=0, le=65535)
    scenes: Path = BUNDLED_SCENES  # the folder scene names resolve in (RCP_SCENES)
    client: Path = CLIENT_DIR  # the browser client's static files
    data: Path = Field(default_factory=default_data)  # uploads, videos and their records (store.py)
    # ---- access ----
    token: SecretStr | None = None  # when set, REST and WebSocket callers must present it
    cors_origins: Annotated[list[str], NoDecode] = []  # origins other pages may call from (comma-separated)
    # names the server answers to besides loopback's (comma-separated; "*": any); none given, a server bound to
    # a loopback address answers only to loopback names, one bound elsewhere to any (access.py)
    allowed_hosts: Annotated[list[str], NoDecode] = []
    # ---- capacity ----
    threads: int = Field(default_factory=default_threads, ge=1, le=256)  # tile workers shared by all renders
    max_renders: int = Field(4, ge=1)  # paintings in progress at once; more wait their turn
    max_waiting: int = Field(16, ge=0)  # REST renders that may wait for a turn; more get 503 and Retry-After
    max_sessions: int = Field(8, ge=1)  # WebSocket walk-throughs at once
    # ---- one request ----
    max_pixels: int = Field(4096 * 2160, ge=1)  # width x height of one image
    max_work: int = Field(1 << 28, ge=1)  # pixels x samples x iterations of one painting (about 30 s here)
    render_timeout_s: float = Field(60.0, gt=0)  # a REST render not done by then (waiting included) gets 503
    max_body_bytes: int = Field(64 * 1024, ge=1024)  # an HTTP request body
    max_message_bytes: int = Field(16 * 1024, ge=256)  # a WebSocket text message; longer ones get an error
    send_timeout_s: float = Field(30.0, gt=0)  # a client that takes no data for this long is disconnected
    # ---- idle and slow connections (guard.py) ----
    header_timeout_s: float = Field(10.0, gt=0)  # a request's headers and body must arrive within this; else 408
    hello_timeout_s: float = Field(10.0, gt=0)  # a WebSocket that has not said hello by then is closed (1008)
    max_connections: int = Field(1024, ge=1)  # open at once; past it the one idle longest is closed
    max_requests: int = Field(128, ge=1)  # HTTP requests in progress at once; more get 503 and Retry-After
    # ---- videos (POST /api/videos), and Ray for them and for large REST renders ----
    max_videos: int = Field(1, ge=1)  # video jobs painting at once (their tiles take turns with the walks')
    max_videos_waiting: int = Field(4, ge=0)  # video jobs that may wait for a turn; more get 503 and Retry-After
    max_video_work: int = Field(1 << 34, ge=1)  # pixels x samples x iterations over every frame of one video
    video_disk_bytes: int = Field(2 << 30, ge=1)  # disk the finished videos may use together
    video_keep_s: float = Field(3600.0, gt=0)  # a finished video is kept this long, then deleted
    ray_address: str | None = None  # paint on Ray: "local" (a runtime here), "auto", host:port, ray://... (below)
    ray_join_s: float = Field(60.0, gt=0)  # with ray_address, start-up fails if Ray has not been joined by then
    ray_min_work: int = Field(1 << 24, ge=1)  # with ray_address, REST renders of this many rays or more go to Ray
    # ---- walking ----
    frame_ms: float = Field(50.0, gt=0)  # while walking, aim for frames at least this fast (20 fps)
    settle_ms: float = Field(150.0, ge=0)  # the camera is at rest after this long without a message
    # with ray_address, walk-throughs are painted on Ray (RCP_RAY_WALKS=0: on the server's threads), each walker
    # admitted while the cluster has room for 1000 / frame_ms frames a second of walk_width x walk_height
    ray_walks: bool = True
    walk_width: int = Field(320, ge=1, le=4096)
    walk_height: int = Field(180, ge=1, le=4096)
    walk_retry_s: int = Field(30, ge=1)  # a walker the cluster has no room for is told to try again after this
    # ---- uploaded scenes (POST /api/scenes) ----
    uploads: bool = True  # RCP_UPLOADS=0 turns uploads off
    upload_max_bytes: int = Field(64 << 20, ge=1024)  # one uploaded file (the body's own limit, not max_body_bytes)
    upload_max_scenes: int = Field(16, ge=1)  # uploaded scenes kept at once
    upload_total_bytes: int = Field(1 << 30, ge=1 << 20)  # the memory all uploaded scenes take together
    upload_max_triangles: int = Field(2_000_000, ge=1)  # in one uploaded model
    upload_max_texture_pixels: int = Field(32 << 20, ge=1)  # all images of one model, width x height
    upload_idle_s: float = Field(1800.0, gt=0)  # an uploaded scene nobody has used this long is removed
    upload_read_s: float = Field(60.0, gt=0)  # the reader of one upload: wall-clock seconds
    upload_memory_bytes: int = Field(2 << 30, ge=64 << 20)  # the reader of one upload: address space it may add

    @field_validator("cors_origins", "allowed_hosts", mode="before")
    @classmethod
    def _comma_separated(cls, value):
        return [origin.strip() for origin in value.split(",") if origin.strip()] if isinstance(value, str) else value

    def upload_limits(self, room_bytes: int | None = None) -> Limits:
        """What the sandbox lets one upload take; ``room_bytes``, the memory the uploaded scenes have left."""
        return Limits(
            max_triangles=self.upload_max_triangles,
            max_texture_pixels=self.upload_max_texture_pixels,
            max_unpacked_bytes=8 * self.upload_max_bytes,  # zipped OBJ text shrinks about 4x; never more than 8
            memory_bytes=self.upload_memory_bytes,
            seconds=self.upload_read_s,
            room_bytes=room_bytes,
        )

    def check_painting(self, width: int, height: int, params: PaintParams) -> None:
        """Refuses (``ValueError``, said to the caller) a painting larger than one request may ask for."""
        if width * height > self.max_pixels:
            raise ValueError(f"{width}x{height} is more than the {self.max_pixels} pixels an image may have")
        work = width * height * params.spp * params.iterations
        if work > self.max_work:
            raise ValueError(
                f"{width}x{height} pixels x {params.spp} spp x {params.iterations} iterations is {work:,} rays, more "
                f"than the {self.max_work:,} one painting may take: ask for fewer pixels, samples or iterations"
            )

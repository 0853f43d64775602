"""Service settings, in one place, read from ``RCP_*`` environment variables (``RCP_PORT=9000``).

Every limit a caller can run into is here, with a default that keeps one 2-core machine serving everyone.
"""

from __future__ import annotations

import difflib
import os
import socket
from pathlib import Path
from typing import Annotated

from pydantic import Field, SecretStr, ValidationError, ValidationInfo, field_validator
from pydantic_core import PydanticUseDefault
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from ..camera.camera import Camera
from ..engine.kernels import embree, screencells
from ..painting.loop import default_threads
from ..scene.untrusted import Limits
from ..settings.params import PaintParams
from .memory import default_memory_bytes

REPOSITORY = Path(__file__).resolve().parent.parent.parent
CLIENT_DIR = REPOSITORY / "client"
BUNDLED_SCENES = REPOSITORY / "scenes"  # RCP_SCENES names another folder: the service reads it once, below


def default_data() -> Path:
    """The user's data directory (XDG): ``$XDG_DATA_HOME/rcp``, else ``~/.local/share/rcp``."""
    return Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share") / "rcp"


class SettingsGroup(BaseSettings):
    """What every group of settings shares: the ``RCP_`` prefix, and an empty value meaning the default."""

    model_config = SettingsConfigDict(env_prefix="RCP_", allow_inf_nan=False)

    @field_validator("*", mode="before")
    @classmethod
    def _empty_is_the_default(cls, value, info: ValidationInfo):
        """An empty value (``RCP_DATA=``, often a variable of a deployment left unset) means the setting's default,
        never the working directory (``Path("")`` is ``.``); an empty token is refused: unset, there is none."""
        if isinstance(value, str) and not value.strip():
            if info.field_name == "token":
                raise ValueError("empty: leave it unset for a server without a token, or give one")
            raise PydanticUseDefault()
        return value


class ServerSettings(SettingsGroup):
    """Where the server listens and the folders it reads and writes."""

    host: str = Field(
        "127.0.0.1", description="the address to listen on: loopback only unless asked (the container sets 0.0.0.0)"
    )
    port: int = Field(8000, ge=0, le=65535, description="the port to listen on")
    scenes: Path = Field(BUNDLED_SCENES, description="the folder scene names resolve in")
    client: Path = Field(CLIENT_DIR, description="the browser client's static files")
    data: Path = Field(
        default_factory=default_data,
        description="uploads, videos and their records (store.py); a volume in the container",
    )

    @field_validator("scenes", "client")
    @classmethod
    def _a_folder(cls, value: Path, info: ValidationInfo) -> Path:
        if not value.is_dir():
            raise ValueError("not a folder" if value.exists() else "no such folder")
        if info.field_name == "client" and not (value / "index.html").is_file():
            raise ValueError("no index.html in it: not the client's folder")
        return value

    @field_validator("data")
    @classmethod
    def _a_folder_or_none_yet(cls, value: Path) -> Path:
        if value.exists() and not value.is_dir():  # a missing one is made at start-up (store.py)
            raise ValueError("not a folder")
        return value

    @field_validator("host")
    @classmethod
    def _an_address_here(cls, value: str) -> str:
        """A name that resolves to addresses of this machine: each one the server will listen on takes a socket
        (port 0 here: whether the port is free is the server's to find out)."""
        try:
            found = socket.getaddrinfo(value, None, socket.AF_UNSPEC, socket.SOCK_STREAM, 0, socket.AI_PASSIVE)
        except (socket.gaierror, UnicodeError) as exc:
            raise ValueError(f"does not resolve ({getattr(exc, 'strerror', None) or exc})") from None
        for family, kind, proto, _, address in found:
            with socket.socket(family, kind, proto) as probe:
                try:
                    probe.bind((address[0], 0, *address[2:]))
                except OSError as exc:
                    raise ValueError(f"not an address of this machine ({exc.strerror or exc})") from None
        return value


class AccessSettings(SettingsGroup):
    """Who may call: the token, the origins and the host names the server answers to."""

    token: SecretStr | None = Field(
        None,
        description="when set, every REST route but /api/health, the API's description and the WebSocket need it, "
        "as Authorization: Bearer <token> or ?token=<token>",
    )
    cors_origins: Annotated[list[str], NoDecode] = Field(
        [], description="origins other pages may call from (comma-separated); CORS is off without them"
    )
    allowed_hosts: Annotated[list[str], NoDecode] = Field(
        [],
        description="names the server answers to besides loopback's (comma-separated; * for any); none given, a "
        "server bound to a loopback address answers only to loopback names (others get 403), one bound elsewhere "
        "to any (access.py)",
    )

    @field_validator("cors_origins", "allowed_hosts", mode="before")
    @classmethod
    def _comma_separated(cls, value):
        return [origin.strip() for origin in value.split(",") if origin.strip()] if isinstance(value, str) else value

    @field_validator("token")
    @classmethod
    def _presentable(cls, value: SecretStr | None) -> SecretStr | None:
        """A token a caller can send as it is: no white space at its ends (a Bearer header loses it), no control
        characters (a header cannot carry them)."""
        text = None if value is None else value.get_secret_value()
        if text is not None and (text != text.strip() or any(ord(c) < 32 or ord(c) == 127 for c in text)):
            raise ValueError("white space at an end or a control character: no caller could present it")
        return value


class CapacitySettings(SettingsGroup):
    """What the server shares among its paintings: threads, turns, walk-throughs and memory."""

    threads: int = Field(
        default_factory=default_threads,
        ge=1,
        le=256,
        description="tile workers shared by all paintings (default: the cores this process may use, at most 32)",
    )
    max_renders: int = Field(4, ge=1, description="paintings in progress at once; more wait their turn")
    max_waiting: int = Field(
        16, ge=0, description="REST renders that may wait for a turn; more get 503 and Retry-After"
    )
    max_sessions: int = Field(
        8,
        ge=1,
        description="WebSocket walk-throughs at once; one more gets an error and close 1013 (the client retries)",
    )
    memory_bytes: int = Field(
        default_factory=default_memory_bytes,
        ge=16 << 20,
        description="the memory the paintings' per-pixel buffers may take together, by their declared bytes a pixel "
        "(memory.py): a walk-through holds its share from its hello until it closes, a REST render, a film or a print "
        "while it paints (a film or a print waits for its share); "
        "a walk that does not fit is refused in one line with the largest size that would, a render gets 503 and "
        "Retry-After (422 if it can never fit) (default: half the memory the machine or container has left as the "
        "server starts, at least 256 MB)",
    )


class RequestLimits(SettingsGroup):
    """How much one request may ask for, and how long it may take."""

    max_pixels: int = Field(4096 * 2160, ge=1, description="width x height of one image or frame; more is a 422")
    max_work: int = Field(
        1 << 28,
        ge=1,
        description="pixels x spp x iterations of one painting (about 30 s here); more is a 422; refinements stay "
        "under it",
    )
    render_timeout_s: float = Field(
        60.0,
        gt=0,
        description="a REST render not done by then (waiting included) stops at its next tile: 503 and Retry-After",
    )
    stop_grace_s: int = Field(
        8,
        ge=0,
        description="on SIGTERM or Ctrl-C, the seconds renders and walk-throughs in flight get to finish; then their "
        "paintings stop at the next tile (503). A second signal stops them at once",
    )
    max_body_bytes: int = Field(
        64 * 1024, ge=1024, description="an HTTP request body, by Content-Length or as it streams; more is a 413"
    )
    max_message_bytes: int = Field(
        16 * 1024,
        ge=256,
        description="a WebSocket text message; a longer one gets an error and the walk goes on; 64x that closes the "
        "socket (1009)",
    )
    send_timeout_s: float = Field(
        30.0, gt=0, description="a client that takes no data this long (WebSocket frames, an HTTP response) is let go"
    )


class ConnectionLimits(SettingsGroup):
    """Idle and slow connections (``guard.py``): how long, how often and how many."""

    header_timeout_s: float = Field(
        10.0,
        gt=0,
        description="a request's headers and body must all be there this long after the connection opened or the "
        "last response ended; else 408 and closed",
    )
    max_messages_per_s: float = Field(
        1000.0,
        gt=0,
        description="WebSocket messages a second one walk-through may send on average (four times that at once); past "
        "it an error and close 1008",
    )
    hello_timeout_s: float = Field(
        10.0, gt=0, description="a WebSocket that has not said hello by then gets an error and close 1008"
    )
    max_connections: int = Field(
        1024, ge=1, description="connections open at once; past it the one idle longest is closed to make room"
    )
    max_requests: int = Field(
        128,
        ge=1,
        description="HTTP requests in progress at once (idle connections do not count); more get 503 and Retry-After",
    )


class FilmSettings(SettingsGroup):
    """Videos (POST /api/videos) and prints, and Ray for them and for large REST renders."""

    max_videos: int = Field(
        1, ge=1, description="video jobs painting at once (their tiles take the cores walks leave); more wait"
    )
    max_videos_waiting: int = Field(
        4, ge=0, description="video jobs that may wait for a turn; more get 503 and Retry-After"
    )
    max_video_work: int = Field(
        1 << 34,
        ge=1,
        description="pixels x spp x iterations over every frame of one video (about half an hour here); more is a 422",
    )
    max_print_work: int = Field(
        1 << 34,
        ge=0,
        description="pixels x spp x iterations of one still at print size (POST /api/prints, with the plain pass "
        "of its alpha); more is a 422, and 0 takes none",
    )
    video_disk_bytes: int = Field(
        2 << 30,
        ge=1,
        description="disk the videos may use together, the frames of those in progress included; a new job whose "
        "estimate (its frames' PNGs at 2 bytes a pixel beside 0.25 bytes a pixel a frame of MP4) does not fit beside "
        "the kept videos and the jobs in progress gets 507 with the estimate and the room left; a film whose next "
        "frame would pass it stops, failed with 507 naming the setting, and keeps what it made until it expires",
    )
    video_keep_s: float = Field(
        3600.0, gt=0, description="a finished video (and its job) is deleted this long after it finished"
    )
    ray_address: str | None = Field(
        None,
        description="paint videos and large REST renders on Ray: local (a Ray runtime on this machine), auto, "
        "host:port or ray://host:port",
    )
    ray_join_s: float = Field(
        60.0,
        gt=0,
        description="with ray_address, rcp serve fails to start (one line, exit 2) if Ray is not joined by then",
    )
    ray_min_work: int = Field(
        1 << 24,
        ge=1,
        description="with ray_address, a REST render of this many rays (pixels x spp x iterations) or more is painted "
        "on Ray; 503 and Retry-After 30 with Ray's one-line fault when Ray fails it, and painted here while Ray backs "
        "off",
    )


class WalkSettings(SettingsGroup):
    """Walking: the frame rate aimed for, rest, and walk-throughs on Ray."""

    frame_ms: float = Field(
        50.0, gt=0, description="while walking, aim for frames at least this fast (20 fps), 80% of it painting"
    )
    settle_ms: float = Field(150.0, ge=0, description="the camera is at rest after this long without a message")
    ray_walks: bool = Field(
        True,
        description="with RCP_RAY_ADDRESS, walk-throughs are painted on Ray (0: on the server's threads), each walker "
        "admitted while the cluster has room for 1000 / frame_ms frames a second of walk_width x walk_height",
    )
    walk_width: int = Field(320, ge=1, le=4096, description="the walk frame size a walker on Ray is admitted for")
    walk_height: int = Field(180, ge=1, le=4096, description="the walk frame size a walker on Ray is admitted for")
    walk_retry_s: int = Field(
        30, ge=1, description="a walker the server or its cluster has no room for is told to try again after this"
    )


class UploadSettings(SettingsGroup):
    """Uploaded scenes (POST /api/scenes): whether, how large, how many, how long kept."""

    uploads: bool = Field(True, description="0 turns uploads off (403)")
    upload_max_bytes: int = Field(
        64 << 20,
        ge=1024,
        description="one uploaded file (its own body limit, not max_body_bytes); more is a 413; a zip may unpack to "
        "8x that",
    )
    upload_max_scenes: int = Field(16, ge=1, description="uploaded scenes kept at once; more get 503 and Retry-After")
    upload_total_bytes: int = Field(
        1 << 30,
        ge=1 << 20,
        description="the memory all uploaded scenes take together; more gets 503 and Retry-After (a file that "
        "declares more triangles than the room left is refused before it is built)",
    )
    upload_max_triangles: int = Field(
        2_000_000, ge=1, description="triangles of one uploaded model, as declared and as read; more is a 422"
    )
    upload_max_texture_pixels: int = Field(
        32 << 20, ge=1, description="the pixels of all images of one model together; more is a 422"
    )
    upload_idle_s: float = Field(
        1800.0, gt=0, description="an uploaded scene nobody has used this long is removed (down time included)"
    )
    upload_read_s: float = Field(
        60.0, gt=0, description="the sandboxed reader of one upload: wall-clock seconds; more is a 422"
    )
    upload_memory_bytes: int = Field(
        2 << 30, ge=64 << 20, description="the sandboxed reader of one upload: address space it may add; more is a 422"
    )

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


class Settings(
    UploadSettings,
    WalkSettings,
    FilmSettings,
    ConnectionLimits,
    RequestLimits,
    CapacitySettings,
    AccessSettings,
    ServerSettings,
):
    """Every ``RCP_`` setting, each declared once with its default, bounds and description (the reference page of
    the documentation is generated from these declarations: ``docs/gen_reference.py``), in its group; the bases
    are listed last group first, so that the fields keep the groups' order (pydantic reads the bases in reverse)."""

    def painting_size(self, camera: Camera, width: int, height: int, params: PaintParams) -> tuple[int, int]:
        """The one decision of every door (REST renders, the walk's ``hello`` and every later camera, view and
        paint message, video jobs): the size of the painting ``camera`` makes of an eye's image of
        ``width x height`` (both eyes of a stereo pair), or a one-line refusal: ``CameraError`` for a size its
        projection does not take, ``ValueError`` for more pixels (both eyes) or more work (all samples, all
        iterations) than one painting may take."""
        size = camera.image_size(width, height)
        pixels = size[0] * size[1]
        if pixels > self.max_pixels:
            raise ValueError(f"{size[0]}x{size[1]} is more than the {self.max_pixels} pixels an image may have")
        work = pixels * params.spp * params.iterations
        if work > self.max_work:
            raise ValueError(
                f"{size[0]}x{size[1]} pixels x {params.spp} spp x {params.iterations} iterations is {work:,} rays, "
                f"more than the {self.max_work:,} one painting may take: ask for fewer pixels, samples or iterations"
            )
        return size


def setting_error(exc: ValidationError, flags: dict[str, str] | None = None) -> str:
    """The first bad setting of ``exc`` in one line, named as its variable (``RCP_SCENES=/nope: no such
    folder``), or as the command-line option that gave it when ``flags`` maps the setting to one (``--host``);
    never the token's value."""
    errors = exc.errors()
    field = str(errors[0]["loc"][0]) if errors[0]["loc"] else ""
    flag = (flags or {}).get(field)
    name, equals = (flag, " ") if flag else (f"RCP_{field.upper()}", "=")
    value = errors[0].get("input")
    shown = f"{equals}{str(value)[:80]}" if field != "token" and isinstance(value, str | int | float | Path) else ""
    message = errors[0]["msg"].removeprefix("Value error, ")
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    return " ".join(f"{name}{shown}: {message}{more}".split())  # one line, whatever the value held


# the RCP_ variables read below the service, by the engine and by Ray's driver process, not settings of the server
ENGINE_VARIABLES = (screencells.VARIABLE, embree.LIBRARY_VARIABLE, "RCP_LOG_LEVEL")


def unknown_variable(environ: dict[str, str]) -> str | None:
    """One line naming the first ``RCP_*`` variable of ``environ`` that nothing reads, with the setting it most
    likely meant (``RCP_MAX_PIXEL``: did you mean ``RCP_MAX_PIXELS``?), else None: a misspelt limit would otherwise
    be ignored and its default served in silence."""
    known = [f"RCP_{name.upper()}" for name in Settings.model_fields] + list(ENGINE_VARIABLES)
    for name in sorted(environ):
        if name.startswith("RCP_") and name not in known:
            close = difflib.get_close_matches(name, known, n=1, cutoff=0.8)
            meant = (
                f": did you mean {close[0]}?"
                if close
                else " (the settings are listed in the reference of the documentation)"
            )
            return f"{name} is no setting of rcp{meant}"
    return None

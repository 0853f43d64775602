"""The wire protocol: every REST body and WebSocket message is a typed model, validated at the edge.

WebSocket messages are JSON text tagged by ``type``; each frame is a ``frame`` text message followed by
one binary message with its JPEG. The browser client mirrors these models through ``client/protocol.js``,
which ``tools/gen_protocol.py`` generates from :func:`schemas` (and the documentation's WebSocket reference
from the same), checked by a test, so the two sides cannot drift apart.
"""

from __future__ import annotations

import json
from typing import Annotated, Any, Literal, get_args

from pydantic import BaseModel, ConfigDict, Field, StrictBool, TypeAdapter, create_model

from ..camera.camera import PROJECTIONS, STEREO
from ..camera.wire import CameraSpec as CameraModel
from ..camera.wire import Coordinate  # a camera on the wire is a camera in a scene file
from ..media.camerapath import MAX_FPS, PathSpec
from ..scene.scenefile import SCENE_NAME
from ..settings.params import PAINT_SETTINGS, PER, PER_PIXEL, PaintSetting
from ..settings.styles import STYLE, STYLES
from .planner import MAX_REFINE_SPP, REFINE_SPP, REFINE_TIMES

Size = Annotated[int, Field(ge=1, le=4096)]
Quality = Annotated[int, Field(ge=1, le=100)]
# a name from the scenes folder, never a path (pydantic's regex and JavaScript's anchor "$" at the very end)
SceneName = Annotated[str, Field(pattern=f"^{SCENE_NAME.pattern}$", examples=["default"])]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


class _Paint(_Model):
    def given(self) -> dict:
        """The settings given, name -> value, ``style`` among them (a null restores the scene's value, so it is
        not one); ``styles.with_style`` applies them."""
        return self.model_dump(exclude_none=True)


def _wire(declared: PaintSetting) -> tuple[Any, Any]:
    """A painting setting on the wire, from its declaration: optional, ``null`` meaning the scene's value."""
    kind: Any  # a type built at run time from the declaration
    if declared.kind is str:
        kind = Literal[declared.choices]  # type: ignore[name-defined]  # the built-in mappings (others: Python only)
    elif declared.kind is bool:
        kind = StrictBool  # true or false, not "yes" or 1
    else:
        bounds = {k: v for k in ("ge", "gt", "le") if (v := getattr(declared, k)) is not None}
        # strict: a number, not true or false (a float setting still takes a whole number)
        kind = Annotated[declared.kind, Field(strict=True, allow_inf_nan=False, **bounds)]
    return kind | None, Field(None, description=declared.help)


OwnPaintModel = create_model(  # type: ignore[call-overload]  # its fields are declared once, in params.py
    "OwnPaintModel",
    __base__=_Paint,
    __doc__="The painting settings an object or a material may set for itself (those that vary per pixel).",
    **{name: _wire(PAINT_SETTINGS[name]) for name in PER_PIXEL},
)

ObjectName = Annotated[str, Field(min_length=1, max_length=200)]

PaintModel = create_model(  # type: ignore[call-overload]  # its fields are declared once, in params.py
    "PaintModel",
    __base__=_Paint,
    __doc__="Painting settings; a field left out takes the scene's value, then the engine's.",
    **{name: _wire(declared) for name, declared in PAINT_SETTINGS.items()},
    **{
        STYLE: (
            Literal[tuple(STYLES)] | None,
            Field(None, description="a named look (GET /api/styles); the settings given beside it override its own"),
        ),
        **{
            per: (
                dict[ObjectName, OwnPaintModel] | None,  # type: ignore[valid-type]
                Field(
                    None,
                    max_length=256,
                    description=f"settings per {per[:-1]} of the scene, by name (merged into the scene's own)",
                ),
            )
            for per in PER
        },
    },
)


class RenderRequest(_Model):
    """``POST /api/render``: every field but ``scene`` has a default (the scene's camera and painting)."""

    scene: SceneName
    width: Size = 640
    height: Size = 360
    camera: CameraModel | None = None
    paint: PaintModel = PaintModel()
    time: Annotated[float, Field(allow_inf_nan=False, ge=0, le=1e6)] = 0.0
    format: Literal["png", "jpeg"] = "png"
    quality: Quality = 92


class CameraPathRef(_Model):
    """A model's animated camera as a path (``camerapath.motion_path``): its name (``SceneInfo.motions``), and
    the frames a second it is sampled at."""

    camera: Annotated[str, Field(min_length=1, max_length=80)]
    fps: Annotated[float, Field(allow_inf_nan=False, gt=0, le=MAX_FPS)] = 24.0


class VideoRequest(_Model):
    """``POST /api/videos``: a camera path (the format of ``camerapath.py``) painted into an MP4; the size and
    painting settings as for a still; ``temporal``: after the first frame, each frame runs this many
    iterations from the previous frame's painting (absent: every frame starts again from grey)."""

    scene: SceneName
    path: PathSpec | CameraPathRef
    width: Size = 640
    height: Size = 360
    paint: PaintModel = PaintModel()
    temporal: Annotated[int, Field(ge=1, le=256)] | None = None
    format: Literal["mp4"] = "mp4"


class PrintRequest(_Model):
    """``POST /api/prints``: a still at print size (up to 16384 a side, painted in bands into a PNG) of an eye's
    image of ``width x height``; ``alpha``: 0 where the plain image sees no geometry; ``bits``: 8 or 16."""

    scene: SceneName
    width: Annotated[int, Field(ge=1, le=16384)] = 4096
    height: Annotated[int, Field(ge=1, le=16384)] = 2304
    camera: CameraModel | None = None
    paint: PaintModel = PaintModel()
    time: Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0, le=1e6)] = 0.0
    alpha: StrictBool = False  # true or false, not 0 or "yes"
    bits: Literal[8, 16] = 8


class PrintStatus(BaseModel):
    """A print job: ``queued``, ``running``, then ``done`` (its PNG ready), ``failed`` or ``cancelled``."""

    id: str
    state: Literal["queued", "running", "done", "failed", "cancelled"]
    rows: int
    done_rows: int
    message: str


class VideoCreated(BaseModel):
    id: str
    frames: int


class VideoStatus(BaseModel):
    """A video job: ``queued``, ``running``, then ``done`` (its file ready), ``failed`` or ``cancelled``."""

    id: str
    state: Literal["queued", "running", "done", "failed", "cancelled"]
    frames: int
    done_frames: int
    message: str


class PathRequest(_Model):
    """``POST /api/paths``: the cameras of a path's frames, for a client to play the path back as it will render;
    ``paint``: the film's painting (as a video's), which the painting the path keys goes over."""

    scene: SceneName
    path: PathSpec | CameraPathRef
    paint: PaintModel = PaintModel()


class PathCameras(BaseModel):
    """Every ``step``-th frame of a path (at most ``PREVIEW_FRAMES`` of them): ``fps`` is theirs. ``paints``: what
    the path keys on each of them over the film's painting, as a ``paint`` table of the settings its keys set
    (within a cross-fade, the painting it fades to); empty when it keys none."""

    fps: float
    step: int
    frames: int  # of the whole path
    cameras: list[CameraModel]
    scene_times: list[float]
    paints: list[dict[str, Any]] = []


class Viewpoint(BaseModel):
    """Another camera a scene offers by name (a glTF's cameras after its first, which is ``camera``)."""

    name: str
    camera: CameraModel


class SceneInfo(BaseModel):
    name: str
    title: str
    camera: CameraModel
    viewpoints: list[Viewpoint] = []
    motions: list[str] = []  # its animated cameras (a glTF's), each a path: {"camera": name} (CameraPathRef)
    paint: dict  # the scene's painting settings that differ from the engine's (client/protocol.js)
    objects: list[str] = []  # what settings per object are called by (the object channel's index)
    materials: list[str] = []  # the named materials, likewise
    animated: bool
    triangles: int
    uploaded: bool = False  # a visitor's (POST /api/scenes): never listed, removed when idle


class StyleInfo(BaseModel):
    """A named look (``GET /api/styles``): ``settings`` are painting settings by name (settings/styles.py)."""

    name: str
    title: str
    description: str
    settings: dict


# ---- WebSocket, client -> server ----


class Hello(_Model):
    """Open (or switch) a walk-through: the scene and the canvas size; the camera resets to the scene's."""

    type: Literal["hello"]
    scene: SceneName
    width: Size = 640
    height: Size = 360
    quality: Quality = 80


class CameraMessage(CameraModel):
    """The newest camera; ``id`` comes back on the frame that shows it (for measuring latency)."""

    type: Literal["camera"]
    id: Annotated[int, Field(ge=0)] | None = None


class PaintMessage(PaintModel):  # type: ignore[misc,valid-type]
    """Change painting settings; given fields replace earlier ones, ``null`` restores the scene's default."""

    type: Literal["paint"]

    def changes(self) -> dict:
        """The settings given, name -> value (``null`` among them); ``objects`` and ``materials`` whole, each
        replacing the walk's earlier ones (then merged into the scene's)."""
        given = {name: getattr(self, name) for name in self.model_fields_set if name != "type"}
        for per in PER:
            if given.get(per) is not None:
                given[per] = {name: own.given() for name, own in given[per].items()}
        return given


class ModeMessage(_Model):
    """``temporal``: each frame continues the recursion from the last one; ``animate``: scene time runs."""

    type: Literal["mode"]
    temporal: bool | None = None
    animate: bool | None = None


class ViewMessage(_Model):
    """Resize the canvas or change the JPEG quality without leaving the scene."""

    type: Literal["view"]
    width: Size | None = None
    height: Size | None = None
    quality: Quality | None = None


class PickMessage(_Model):
    """Which object and material pixel ``(x, y)`` of the canvas (``width x height`` of the walk) shows, seen by
    the newest camera: the server answers ``picked``."""

    type: Literal["pick"]
    x: Annotated[int, Field(ge=0, le=4095)]
    y: Annotated[int, Field(ge=0, le=4095)]


Vector = tuple[Coordinate, Coordinate, Coordinate]


class MoveMessage(_Model):
    """Walking, not flying: move the eye at ``eye`` by ``delta`` (scene units, world axes; gravity is a downward
    delta) and keep clear of the scene's surfaces (engine/collide.py): the server answers ``moved`` with where
    it ends. ``height``: the eye's height above the floor it stands on, as the last ``moved`` said (null:
    measured here, at ``eye``)."""

    type: Literal["move"]
    id: Annotated[int, Field(ge=0)]
    eye: Vector
    delta: Vector
    height: Annotated[float, Field(allow_inf_nan=False, gt=0, le=1e9)] | None = None


ClientMessage = Annotated[
    Hello | CameraMessage | PaintMessage | ModeMessage | ViewMessage | PickMessage | MoveMessage,
    Field(discriminator="type"),
]
client_message: TypeAdapter[Any] = TypeAdapter(ClientMessage)


# ---- WebSocket, server -> client ----


class RefineRule(BaseModel):
    """How a view at rest is refined (``service/planner.py``): its own samples per pixel, then
    ``min(most, max(least, times * spp))`` where the server's work limit allows; what Save asks for too."""

    least: int = REFINE_SPP
    most: int = MAX_REFINE_SPP
    times: int = REFINE_TIMES


class Ready(BaseModel):
    """The answer to ``hello``: the scene, the canvas and the switches the walk starts with."""

    type: Literal["ready"] = "ready"
    scene: SceneInfo
    width: int
    height: int
    quality: int
    temporal: bool
    animate: bool
    refine: RefineRule = RefineRule()


class Frame(BaseModel):
    """Sent before the binary JPEG it describes: the painting of camera ``camera_id`` at ``width`` x
    ``height`` with ``paint`` (what ``POST /api/render`` gives for the same, up to the JPEG). ``phase``:
    ``walk`` while the camera moves (reduced in size and samples), ``refine`` once it rests; ``final`` when
    no further refinement follows; ``temporal``: it continues the last frame instead; ``projection`` and
    ``stereo``: the camera's, so the client knows how to show the picture (both eyes of a pair in one image)."""

    type: Literal["frame"] = "frame"
    seq: int
    width: int
    height: int
    render_ms: float
    iteration: int  # iterations of the recursion behind this image (temporal mode keeps counting)
    spp: int
    scale: float  # frame size / canvas size
    phase: Literal["walk", "refine"]
    final: bool
    temporal: bool
    quality: int  # of the JPEG: lower while walking
    paint: dict[str, bool | int | float | str | dict | None]  # every painting setting of this image (spp included)
    camera_id: int | None
    time: float
    dropped: int  # frames rendered but never sent, because a newer one replaced them
    projection: Literal[PROJECTIONS] = "perspective"  # type: ignore[valid-type]
    stereo: Literal[STEREO] = "mono"  # type: ignore[valid-type]
    # painted in bands on several machines: each band's [first row, rows], top to bottom; one binary JPEG a band
    # follows instead of one for the frame, each drawn at its rows (the frame shows once all are in)
    bands: list[tuple[int, int]] | None = None


ClientType = Literal["hello", "camera", "paint", "mode", "view", "pick", "move"]


class Error(BaseModel):
    """A refusal or a failure, in one line. ``answers``: the type of the client message refused (null: none, e.g.
    a painting that failed, or a message whose type cannot be read); ``id``: that message's ``id``, if it had one
    (``camera``, ``move``)."""

    type: Literal["error"] = "error"
    message: str
    answers: ClientType | None = None
    id: int | None = None

    @classmethod
    def answering(cls, text: str | None, message: str) -> Error:
        """The error ``message`` answering the client's message ``text`` (raw JSON, perhaps invalid): its type and
        id are named when they can be read."""
        try:
            sent = json.loads(text) if text else None
        except ValueError:
            sent = None
        if not isinstance(sent, dict):
            return cls(message=message)
        kind, ident = sent.get("type"), sent.get("id")
        return cls(
            message=message,
            answers=kind if kind in get_args(ClientType) else None,
            id=ident if type(ident) is int and ident >= 0 else None,
        )


class PickMask(BaseModel):
    """The pixels of a view that show the picked object, at ``width x height`` (the view's shape, smaller):
    ``bits`` is base64 of the row-major bits, eight pixels a byte, the first the highest bit (numpy packbits)."""

    width: int
    height: int
    bits: str


class Picked(BaseModel):
    """The answer to ``pick``: the object and material names there (``paint.objects`` and ``paint.materials``
    take them), null for the sky; a material with no name is ""."""

    type: Literal["picked"] = "picked"
    x: int
    y: int
    object: str | None
    material: str | None
    mask: PickMask | None = None  # where the object shows in the view, for the client to outline it


class Moved(BaseModel):
    """The answer to ``move`` ``id``: where the eye ends, and the body that kept it clear: ``radius`` (scene
    units from any surface), ``height`` above the floor (null: nothing beneath, it flies), ``standing`` on it."""

    type: Literal["moved"] = "moved"
    id: int
    eye: tuple[float, float, float]
    radius: float
    height: float | None
    standing: bool


CLIENT_MESSAGES = (Hello, CameraMessage, PaintMessage, ModeMessage, ViewMessage, PickMessage, MoveMessage)
SERVER_MESSAGES = (Ready, Frame, Error, Picked, Moved)


def schemas() -> dict[str, Any]:
    """The JSON schema of every message, by side and type, of the painting settings (``paint``) and of a camera
    (``camera``): what ``tools/gen_protocol.py`` writes into ``client/protocol.js`` and the WebSocket reference."""
    return {
        "client": {get_args(m.model_fields["type"].annotation)[0]: m.model_json_schema() for m in CLIENT_MESSAGES},
        "server": {m.model_fields["type"].default: m.model_json_schema() for m in SERVER_MESSAGES},
        "paint": PaintModel.model_json_schema(),
        "camera": CameraModel.model_json_schema(),
    }

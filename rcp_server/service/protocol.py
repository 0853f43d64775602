"""The wire protocol: every REST body and WebSocket message is a typed model, validated at the edge.

WebSocket messages are JSON text tagged by ``type``; each frame is a ``frame`` text message followed by
one binary message with its JPEG. The browser client mirrors these models through ``client/protocol.js``,
which is generated from this module (``python -m rcp_server.service.protocol > client/protocol.js``) and
checked by a test, so the two sides cannot drift apart.
"""

from __future__ import annotations

import json
from typing import Annotated, Any, Literal, get_args

from pydantic import BaseModel, ConfigDict, Field, StrictBool, TypeAdapter, create_model

from ..camera.wire import CameraSpec as CameraModel  # a camera on the wire is a camera in a scene file
from ..media.camerapath import PathSpec
from ..scene.scenefile import SCENE_NAME
from ..settings.params import PAINT_SETTINGS, PER, PER_PIXEL, PaintParams, PaintSetting
from ..settings.styles import STYLE, STYLES

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
        kind = Annotated[declared.kind, Field(allow_inf_nan=False, **bounds)]
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


class VideoRequest(_Model):
    """``POST /api/videos``: a camera path (the format of ``camerapath.py``) painted into an MP4; the size and
    painting settings as for a still; ``temporal``: after the first frame, each frame runs this many
    iterations from the previous frame's painting (absent: every frame starts again from grey)."""

    scene: SceneName
    path: PathSpec
    width: Size = 640
    height: Size = 360
    paint: PaintModel = PaintModel()
    temporal: Annotated[int, Field(ge=1, le=256)] | None = None
    format: Literal["mp4"] = "mp4"


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
    """``POST /api/paths``: the cameras of a path's frames, for a client to play the path back as it will render."""

    scene: SceneName
    path: PathSpec


class PathCameras(BaseModel):
    """Every ``step``-th frame of a path (at most ``PREVIEW_FRAMES`` of them): ``fps`` is theirs."""

    fps: float
    step: int
    frames: int  # of the whole path
    cameras: list[CameraModel]
    scene_times: list[float]


class Viewpoint(BaseModel):
    """Another camera a scene offers by name (a glTF's cameras after its first, which is ``camera``)."""

    name: str
    camera: CameraModel


class SceneInfo(BaseModel):
    name: str
    title: str
    camera: CameraModel
    viewpoints: list[Viewpoint] = []
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


Coordinate = Annotated[float, Field(allow_inf_nan=False, ge=-1e9, le=1e9)]
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


class Ready(BaseModel):
    type: Literal["ready"] = "ready"
    scene: SceneInfo
    width: int
    height: int
    quality: int
    temporal: bool
    animate: bool


class Frame(BaseModel):
    """Sent before the binary JPEG it describes: the painting of camera ``camera_id`` at ``width`` x
    ``height`` with ``paint`` (what ``POST /api/render`` gives for the same, up to the JPEG). ``phase``:
    ``walk`` while the camera moves (reduced in size and samples), ``refine`` once it rests; ``final`` when
    no further refinement follows; ``temporal``: it continues the last frame instead."""

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
    # painted in bands on several machines: each band's [first row, rows], top to bottom; one binary JPEG a band
    # follows instead of one for the frame, each drawn at its rows (the frame shows once all are in)
    bands: list[tuple[int, int]] | None = None


class Error(BaseModel):
    type: Literal["error"] = "error"
    message: str


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


def schemas() -> dict[str, Any]:
    """The JSON schema of every message, by side and type, and of the painting settings (``paint``): what
    ``client/protocol.js`` exports as ``PROTOCOL``."""
    return {
        "client": {get_args(m.model_fields["type"].annotation)[0]: m.model_json_schema() for m in _CLIENT},
        "server": {m.model_fields["type"].default: m.model_json_schema() for m in (Ready, Frame, Error, Picked, Moved)},
        "paint": PaintModel.model_json_schema(),
    }


class _Js:
    """A JavaScript expression in the generated module: a constant's name, or an object spread over one."""

    def __init__(self, base: str, changes: dict[str, Any] | None = None):
        self.base, self.changes = base, changes


def _shared(value: Any, base: Any, name: str) -> Any:
    """``value`` with whatever equals ``base`` written as a reference to the constant ``name`` that holds it: all
    of it, or an object spread over it with the keys that differ (``{...PAINT, "title": "PaintMessage"}``)."""
    if value == base:
        return _Js(name)
    if isinstance(value, dict) and isinstance(base, dict) and base.keys() <= value.keys():
        changes = {k: _shared(v, base.get(k), f"{name}[{json.dumps(k)}]") for k, v in value.items() if v != base.get(k)}
        return _Js(name, changes)
    return value


def _js(value: Any, indent: int = 0) -> str:
    """``value`` as JavaScript: JSON (``indent=1``, sorted keys), with :class:`_Js` expressions in place."""
    pad, inner = " " * indent, " " * (indent + 1)
    if isinstance(value, _Js):
        if value.changes is None:
            return value.base
        entries = [f"...{value.base}"] + [
            f"{json.dumps(k)}: {_js(v, indent + 1)}" for k, v in sorted(value.changes.items())
        ]
        return "{\n" + ",\n".join(inner + e for e in entries) + "\n" + pad + "}"
    if isinstance(value, dict) and value:
        entries = [f"{json.dumps(k)}: {_js(v, indent + 1)}" for k, v in sorted(value.items())]
        return "{\n" + ",\n".join(inner + e for e in entries) + "\n" + pad + "}"
    if isinstance(value, list) and value:
        return "[\n" + ",\n".join(inner + _js(v, indent + 1) for v in value) + "\n" + pad + "]"
    return json.dumps(value)


def client_module() -> str:
    """``client/protocol.js``: the JSON schema of every message, for the browser to build and check against,
    and the engine's painting defaults (``null``: derived per view), for the settings a scene leaves out.

    The painting settings' schemas are written once (``PAINT_PROPERTIES``) and referenced wherever a schema
    holds them again: the settings an object or material may set (``OWN_PAINT``), the paint schema (``PAINT``)
    and the ``paint`` message, which is the paint schema and its ``type``."""
    every = schemas()
    paint = every["paint"]
    properties = paint["properties"]
    own = paint["$defs"]["OwnPaintModel"]
    own_js = {
        **own,
        "properties": {
            k: _Js(f"PAINT_PROPERTIES[{json.dumps(k)}]") if v == properties.get(k) else v
            for k, v in own["properties"].items()
        },
    }
    paint_js = {
        **paint,
        "$defs": {**paint["$defs"], "OwnPaintModel": _Js("OWN_PAINT")},
        "properties": _Js("PAINT_PROPERTIES"),
    }
    protocol = {**every, "paint": _Js("PAINT")}
    protocol["client"] = {**every["client"], "paint": _shared(every["client"]["paint"], paint, "PAINT")}
    defaults = json.dumps(PaintParams().settings(), indent=1)
    return (
        "// Generated by `python -m rcp_server.service.protocol > client/protocol.js`; do not edit.\n"
        "// The painting settings' JSON schemas, once (rcp_server/settings/params.py, through service/protocol.py).\n"
        f"const PAINT_PROPERTIES = {_js(properties)};\n"
        "// The settings an object or a material may set for itself.\n"
        f"const OWN_PAINT = {_js(own_js)};\n"
        "// The painting settings of a request or a message.\n"
        f"const PAINT = {_js(paint_js)};\n"
        "// The JSON schemas of the WebSocket messages (rcp_server/service/protocol.py).\n"
        f"export const PROTOCOL = {_js(protocol)};\n"
        "// The engine's painting settings (rcp_server/settings/params.py), for those a scene leaves out.\n"
        f"export const ENGINE_DEFAULTS = {defaults};\n"
    )


_CLIENT = (Hello, CameraMessage, PaintMessage, ModeMessage, ViewMessage, PickMessage, MoveMessage)

if __name__ == "__main__":
    print(client_module(), end="")

"""The camera as scene files, requests and camera paths write it: pydantic models derived from the one
declaration, :data:`camera.CAMERA_FIELDS`, so that a new camera field reaches every one of them (and the
command line, ``cli.py``, and the client, ``client/protocol.js``) or a test fails.
"""

from __future__ import annotations

from dataclasses import asdict
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, create_model

from .camera import CAMERA_FIELDS, COORDINATE_LIMIT, Camera, CameraField

# how far a camera may stand is the engine's rule (camera.camera_faults), said here too so that the schema a
# client reads (client/protocol.js) carries it
Coordinate = Annotated[float, Field(allow_inf_nan=False, ge=-COORDINATE_LIMIT, le=COORDINATE_LIMIT)]
Vec3 = tuple[Coordinate, Coordinate, Coordinate]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def field_type(declared: CameraField) -> Any:
    """The pydantic type of one declared camera field, its bounds included."""
    if declared.kind == "vec3":
        return Vec3
    if declared.kind is str:
        return Literal[declared.choices]  # type: ignore[valid-type]
    bounds = {k: getattr(declared, k) for k in ("gt", "ge", "lt") if getattr(declared, k) is not None}
    return Annotated[float, Field(allow_inf_nan=False, le=COORDINATE_LIMIT, **bounds)]


def camera_fields(optional: frozenset[str] = frozenset()) -> dict[str, Any]:
    """Every camera field as ``create_model`` takes it: required where the declaration has no default, the
    declared default otherwise; the names in ``optional`` default to None (a keyframe's "as before")."""
    out = {}
    for name, declared in CAMERA_FIELDS.items():
        kind = field_type(declared)
        if name in optional:
            out[name] = (kind | None, Field(None, description=declared.help))
        elif declared.required:
            out[name] = (kind, Field(..., description=declared.help))
        else:
            out[name] = (kind, Field(declared.default, description=declared.help))
    return out


CameraSpec = create_model(  # type: ignore[call-overload]
    "CameraSpec",
    __base__=_Model,
    __doc__="A camera (MISSION.md conventions): ``fov`` is the vertical field of view in degrees.",
    **camera_fields(),
)


def camera_of(spec: BaseModel) -> Camera:
    """The engine's camera of a :data:`CameraSpec` (every field by name: none is dropped)."""
    return Camera(**{name: getattr(spec, name) for name in CAMERA_FIELDS})


def spec_of(camera: Camera) -> BaseModel:
    """The wire's camera of an engine camera."""
    return CameraSpec(**asdict(camera))

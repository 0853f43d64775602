"""Scene files: small declarative TOML in ``scenes/``, validated once, turned into a :class:`Scene`.

A scene is referred to by name (``default`` -> ``scenes/default.toml``); a name is letters, digits,
``-`` and ``_`` only, so it never reaches outside the scenes folder. ``load_scene`` also takes a scene
file path or a bare mesh file path (lit and framed with defaults). See ``scenes/README.md`` for the
format; every key is checked and a broken file is reported in one line naming the file.
"""

from __future__ import annotations

import logging
import math
import os
import re
import tomllib
import zlib
from dataclasses import replace
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import trimesh
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from ..camera.camera import COORDINATE_LIMIT, Camera, CameraError
from ..camera.wire import CameraSpec, camera_of
from ..settings.params import PaintParams
from . import framing
from .meshes import (
    DEFAULT_ALBEDO,
    Material,
    MeshError,
    Model,
    Part,
    load_model,
    load_texture,
    primitive,
    read_image,
    release_freed_memory,
)
from .radiance import read_radiance, tonemap
from .scene import Environment, Light, Scene, SceneObject, Waves

log = logging.getLogger("rcp")

SCENES_DIR = Path(os.environ.get("RCP_SCENES", Path(__file__).resolve().parents[2] / "scenes"))
SCENE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}")  # always with fullmatch: "$" would let a newline in


class SceneError(ValueError):
    """A scene that cannot be loaded; the message is one line naming the file and the fault."""


# ---- the file format ----

Finite = Annotated[float, Field(allow_inf_nan=False)]
Vec3 = tuple[Finite, Finite, Finite]
Color = tuple[
    Annotated[float, Field(ge=0, le=1)], Annotated[float, Field(ge=0, le=1)], Annotated[float, Field(ge=0, le=1)]
]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class EnvironmentSpec(_Model):
    image: str | None = None
    color: Color | None = None
    exposure: Finite = 0.0  # stops, for a Radiance .hdr image


class LightSpec(_Model):
    direction: Vec3 = (-0.4, -1.0, -0.3)
    ambient: Annotated[float, Field(ge=0, le=1)] = 0.3


class PrimitiveSpec(_Model):
    type: Literal["box", "sphere", "cylinder", "cone", "grid"]
    extents: Vec3 | None = None
    radius: Annotated[float, Field(gt=0)] | None = None
    height: Annotated[float, Field(gt=0)] | None = None
    sections: Annotated[int, Field(ge=3, le=512)] | None = None
    subdivisions: Annotated[int, Field(ge=0, le=6)] | None = None
    size: tuple[Annotated[float, Field(gt=0)], Annotated[float, Field(gt=0)]] | None = None
    divisions: tuple[Annotated[int, Field(ge=1, le=2048)], Annotated[int, Field(ge=1, le=2048)]] | None = None
    uv_repeat: tuple[Finite, Finite] | None = None


class Placement(_Model):
    translate: Vec3 = (0.0, 0.0, 0.0)
    rotate: Vec3 = (0.0, 0.0, 0.0)  # degrees about x, then y, then z
    scale: Annotated[float, Field(gt=0)] | tuple[Finite, Finite, Finite] = 1.0

    def matrix(self) -> np.ndarray:
        rx, ry, rz = np.radians(self.rotate)
        m = trimesh.transformations.euler_matrix(rx, ry, rz, axes="sxyz")
        m[:3, :3] = m[:3, :3] * np.broadcast_to(np.asarray(self.scale, dtype=np.float64), (3,))
        m[:3, 3] = self.translate
        return m


class ScatterSpec(_Model):
    count: Annotated[int, Field(ge=1, le=10000)]
    area: tuple[Finite, Finite, Finite, Finite]  # x_min, x_max, z_min, z_max on the ground (y = 0)
    scale: tuple[Annotated[float, Field(gt=0)], Annotated[float, Field(gt=0)]] = (1.0, 1.0)
    keep_out: list[tuple[Finite, Finite, Annotated[float, Field(ge=0)]]] = []  # circles (x, z, radius)
    seed: int = 0


class SpinSpec(_Model):
    axis: Vec3 = (0.0, 1.0, 0.0)
    degrees_per_second: Finite = 30.0


class BobSpec(_Model):
    height: Finite = 0.2
    period: Annotated[float, Field(gt=0)] = 2.0


class WaveSpec(_Model):
    amplitude: Finite
    wavelength: Annotated[float, Field(gt=0)]
    direction: tuple[Finite, Finite] = (1.0, 0.0)
    speed: Finite = 1.0

    @field_validator("direction")
    @classmethod
    def _nonzero(cls, v):
        if math.hypot(*v) == 0:
            raise ValueError("direction must not be zero")
        return v


class ObjectSpec(Placement):
    """An object: one mesh or primitive, its colors, where it stands (once, in instances, or scattered),
    and how it moves."""

    name: str = ""
    mesh: str | None = None
    primitive: PrimitiveSpec | None = None
    color: Color | None = None
    texture: str | None = None
    palette: list[Color] = []
    color_jitter: Annotated[float, Field(ge=0, le=1)] = 0.0
    instances: list[Placement] = []
    scatter: ScatterSpec | None = None
    spin: SpinSpec | None = None
    bob: BobSpec | None = None
    waves: list[WaveSpec] = []
    material: str | None = None  # a name from the scene's [materials]
    paint: dict[str, str | int | float | bool] = {}  # this object's own painting (params.PER_PIXEL)

    @model_validator(mode="after")
    def _one_placement_list(self):
        if self.instances and self.scatter is not None:
            raise ValueError("give 'instances' or 'scatter', not both")
        return self


class MaterialSpec(_Model):
    """A material objects refer to by name: how it is shaded, and its own painting (``params.PER_PIXEL``)."""

    shading: Literal["lit", "toon"] = "lit"
    bands: Annotated[int, Field(ge=1, le=16)] = 3  # toon: flat bands of light
    outline: Annotated[float, Field(ge=0, le=1)] = 0.0  # ink where object, normal or depth jump (0: none)
    paint: dict[str, str | int | float | bool] = {}


class SceneSpec(_Model):
    title: str = ""
    camera: CameraSpec | str  # type: ignore[valid-type]  # or the name of a camera in one of the objects' glTF files
    environment: EnvironmentSpec = EnvironmentSpec(color=(0.55, 0.62, 0.72))
    light: LightSpec | str | None = None  # or the name of a light (KHR_lights_punctual) in one of them
    paint: dict[str, str | int | float | bool] = {}
    z_max: Annotated[float, Field(gt=0)] | None = None
    materials: dict[str, MaterialSpec] = {}
    objects: list[ObjectSpec] = []


# ---- from spec to scene ----


def _instances(spec: ObjectSpec) -> list[np.ndarray]:
    if spec.scatter is None:
        return [p.matrix() for p in spec.instances] or [np.eye(4)]
    sc = spec.scatter
    rng = np.random.default_rng(sc.seed)
    placed: list[np.ndarray] = []
    for _ in range(sc.count * 50):  # rejection sampling around keep-out circles, bounded
        if len(placed) == sc.count:
            break
        x, z = rng.uniform(sc.area[0], sc.area[1]), rng.uniform(sc.area[2], sc.area[3])
        yaw, scale = rng.uniform(0.0, 360.0), rng.uniform(*sc.scale)
        if any(math.hypot(x - cx, z - cz) < r for cx, cz, r in sc.keep_out):
            continue
        placed.append(Placement(translate=(x, 0.0, z), rotate=(0.0, yaw, 0.0), scale=scale).matrix())
    if len(placed) < sc.count:
        log.warning(
            "%s: scatter placed %d of %d copies; the keep-out circles cover most of its area",
            spec.name or "an object",
            len(placed),
            sc.count,
        )
    return placed


def _tints(spec: ObjectSpec, count: int, base) -> np.ndarray:
    """Albedo multiplier per instance: (count, 3): ``base``, or picks from the palette, then jittered."""
    rng = np.random.default_rng(zlib.crc32(spec.name.encode()))  # stable across runs, unlike hash()
    colors = np.tile(np.asarray(base, dtype=np.float64), (count, 1))
    if spec.palette:
        colors = np.asarray(spec.palette, dtype=np.float64)[rng.integers(0, len(spec.palette), count)]
    if spec.color_jitter:
        colors = colors * (1.0 + spec.color_jitter * rng.uniform(-1.0, 1.0, (count, 3)))
    return np.clip(colors, 0.0, 1.0)


def _motion(spec: ObjectSpec):
    if spec.spin is None and spec.bob is None:
        return None
    spin, bob = spec.spin, spec.bob

    def motion(time: float) -> np.ndarray:
        m = np.eye(4)
        if spin is not None:
            m = trimesh.transformations.rotation_matrix(math.radians(spin.degrees_per_second * time), spin.axis)
        if bob is not None:
            m[1, 3] += bob.height * math.sin(2.0 * math.pi * time / bob.period)
        return m

    return motion


def _model(spec: ObjectSpec, folder: Path, where: str) -> Model:
    if (spec.mesh is None) == (spec.primitive is None):
        raise SceneError(f"{where}: give exactly one of 'mesh' or 'primitive'")
    if spec.mesh is not None:
        return load_model(folder / spec.mesh)
    p = spec.primitive
    assert p is not None  # one of the two, checked above
    return Model([primitive(p.type, **{k: v for k, v in p.model_dump().items() if k != "type" and v is not None})])


class _Named:
    """The cameras and lights that the objects' model files bring, by name, each with the placement of its
    object's first copy (4x4): what a scene file's ``camera = "name"`` and ``light = "name"`` refer to."""

    def __init__(self):
        self.cameras: dict = {}
        self.lights: dict = {}

    def add(self, model: Model, world_from_model: np.ndarray) -> None:
        for viewpoint in model.viewpoints:
            self.cameras.setdefault(viewpoint.name, (viewpoint, world_from_model))
        for light in model.lights:
            self.lights.setdefault(light.name, (light, world_from_model))

    def camera(self, name: str, scene: Scene) -> Camera:
        if name not in self.cameras:
            raise SceneError(
                f"camera: no camera named {name!r} in the objects' files (they have: {_listed(self.cameras)})"
            )
        geometry, tracer = scene.geometry(0.0)
        viewpoint, placement = self.cameras[name]
        return framing.viewpoint_camera(viewpoint, geometry, tracer, placement)

    def light(self, name: str, scene: Scene) -> Light:
        if name not in self.lights:
            raise SceneError(
                f"light: no light named {name!r} in the objects' files (they have: {_listed(self.lights)})"
            )
        light, placement = self.lights[name]
        return framing.light_of([light], scene.geometry(0.0)[0], placement)


def _listed(names) -> str:
    return ", ".join(repr(n) for n in list(names)[:8]) or "none"


def _scene_object(
    spec: ObjectSpec, folder: Path, where: str, named: _Named | None = None, material: Material | None = None
) -> list[SceneObject]:
    """The parts of one object of a scene file; ``material``: the one its ``material`` names (over the parts'
    own, keeping their emission and cut-outs)."""
    objects = []
    texture = read_image(folder / spec.texture) if spec.texture else None
    placements = [m @ spec.matrix() for m in _instances(spec)]
    model = _model(spec, folder, where)
    if named is not None and placements:
        named.add(model, placements[0])
    motion = _motion(spec)
    waves = tuple(Waves(w.amplitude, w.wavelength, w.direction, w.speed) for w in spec.waves)
    for k, part in enumerate(model.parts):
        if texture is not None:
            if part.corner_uv is None:
                raise SceneError(f"{where}: 'texture' needs a mesh with texture coordinates")
            part = replace(part, texture=texture)
        # 'color' multiplies the colors a part carries (and any texture); a plain part takes it as albedo
        if not part.colored:
            part = replace(part, corner_colors=np.ones_like(part.corner_colors))
        if material is not None:
            shared = (
                material if part.material.plain else replace(part.material, name=material.name, bands=material.bands)
            )
            part = replace(part, material=shared)
        white = part.colored or part.texture is not None
        base = spec.color if spec.color is not None else ((1.0, 1.0, 1.0) if white else DEFAULT_ALBEDO)
        tints = _tints(spec, len(placements), base)
        instances = [(m, part.tinted(tint)) for m, tint in zip(placements, tints, strict=True)]
        name = spec.name or where
        objects.append(SceneObject(f"{name}#{k}", part, instances, motion, waves, label=name))
    return objects


def one_line(exc: ValidationError) -> str:
    """A validation error as one readable line: ``where: problem (and n more)``."""
    problems = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"])
        problems.append(f"{loc}: {err['msg']}" if loc else err["msg"])
    more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
    return problems[0] + more


def _environment(env: EnvironmentSpec, folder: Path) -> Environment:
    """The scene file's environment: an image beside it, or a constant color."""
    if (env.image is None) == (env.color is None):
        raise SceneError("environment: give exactly one of 'image' or 'color'")
    return load_environment(folder / env.image, env.exposure) if env.image else Environment.constant(env.color)


def _light(spec: LightSpec | str | None) -> Light | None:
    """The scene file's own light (a named glTF light is placed once the scene is built)."""
    if not isinstance(spec, LightSpec):
        return None
    d = np.asarray(spec.direction, dtype=np.float64)
    if np.linalg.norm(d) == 0:
        raise SceneError("light.direction must not be zero")
    return Light(tuple(d / np.linalg.norm(d)), spec.ambient)


def _objects(specs: list[ObjectSpec], folder: Path, named: _Named, materials: dict[str, Material]) -> list[SceneObject]:
    """The scene file's objects, each made of its material from ``[materials]``."""
    objects = []
    for index, obj in enumerate(specs):
        where = f"objects.{index}" + (f" ({obj.name})" if obj.name else "")
        if obj.material is not None and obj.material not in materials:
            raise SceneError(f"{where}: no material {obj.material!r} in [materials] (it has: {_listed(materials)})")
        objects.extend(_scene_object(obj, folder, where, named, materials.get(obj.material or "")))
    return objects


def load_scene_file(path: Path, name: str | None = None) -> Scene:
    """A scene from a TOML scene file; every fault is a :class:`SceneError` naming the file."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SceneError(f"{path}: cannot read ({exc.strerror})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SceneError(f"{path}: not valid TOML ({exc})") from None
    try:
        spec = SceneSpec.model_validate(raw)
    except ValidationError as exc:
        raise SceneError(f"{path}: {one_line(exc)}") from None
    folder = path.parent
    try:
        named = _Named()
        camera = camera_of(spec.camera) if isinstance(spec.camera, CameraSpec) else None
        materials = {
            name: Material(name=name, bands=m.bands if m.shading == "toon" else 0, outline=m.outline)
            for name, m in spec.materials.items()
        }
        per_object = {obj.name or f"objects.{index}": obj.paint for index, obj in enumerate(spec.objects) if obj.paint}
        per_material = {name: m.paint for name, m in spec.materials.items() if m.paint}
        # refuse bad painting settings now, not at the first render
        paint = PaintParams.from_dict({**spec.paint, "objects": per_object, "materials": per_material})
        stand_in = Camera((0.0, 0.0, 1.0), (0.0, 0.0, 0.0))  # until the named camera is placed in the scene
        scene = Scene(
            name or path.stem,
            spec.title or path.stem,
            camera or stand_in,
            _environment(spec.environment, folder),
            _light(spec.light),
            _objects(spec.objects, folder, named, materials),
            paint,
            spec.z_max,
        )
        scene.check_names(paint)  # a [materials] table's painting for a material no object is made of
        # ---- the cameras and lights of the objects' glTF files, by name ----
        if isinstance(spec.light, str):
            scene.light = named.light(spec.light, scene)
        if isinstance(spec.camera, str):
            scene.camera = named.camera(spec.camera, scene)
        scene.viewpoints = {n: named.camera(n, scene) for n in named.cameras if n != spec.camera}
    except (SceneError, MeshError, CameraError, ValueError) as exc:
        message = str(exc)
        raise SceneError(message if message.startswith(str(path)) else f"{path}: {message}") from None
    return scene


def load_environment(path: Path, exposure: float = 0.0) -> Environment:
    """An equirectangular panorama: a Radiance ``.hdr`` (tonemapped at ``exposure`` stops) or any image
    Pillow reads (taken as display colors)."""
    if Path(path).suffix.lower() == ".hdr":
        return Environment(tonemap(read_radiance(path), exposure))
    return Environment(load_texture(path))


def frame_camera(parts: list[Part], fov: float = 45.0) -> Camera:
    """A camera that frames ``parts`` from the front, a little above and to the right. Raises
    :class:`SceneError` for a model too large or too far from the origin for any valid camera to frame."""
    points = np.concatenate([p.vertices[p.faces].reshape(-1, 3) for p in parts])
    lo, hi = points.min(axis=0), points.max(axis=0)
    with np.errstate(all="ignore"):  # a model near the float64 limit: its size is infinite, refused below
        center, radius = (lo + hi) / 2, max(float(np.linalg.norm(hi - lo)) / 2, 1e-6)
        distance = radius / math.sin(math.radians(fov) / 2) * 1.05
        view = np.array([0.45, 0.35, 1.0]) / np.linalg.norm([0.45, 0.35, 1.0])
        eye = center + distance * view
    try:
        return Camera(tuple(eye), tuple(center), fov=fov)
    except CameraError:
        raise SceneError(
            f"the model spans from ({', '.join(f'{x:.3g}' for x in lo)}) to ({', '.join(f'{x:.3g}' for x in hi)}): "
            f"too large, or too far from the origin, for a camera within +-{COORDINATE_LIMIT:g} scene units to "
            "frame it"
        ) from None


def mesh_scene(path: Path) -> Scene:
    """A bare mesh file as a scene: its own cameras and light if it has them, a calm backdrop."""
    try:
        model = load_model(path)
    except MeshError as exc:
        raise SceneError(str(exc)) from None
    return model_scene(model, Path(path).stem, Path(path).name)


def _unique(names: list[str]) -> list[str]:
    seen: dict[str, int] = {}
    out = []
    for name in names:
        seen[name] = seen.get(name, 0) + 1
        out.append(name if seen[name] == 1 else f"{name} ({seen[name]})")
    return out


def model_scene(model: Model, name: str, title: str) -> Scene:
    """A model as a scene, as its authors made it where they said (``framing.py``): its first camera is the
    scene's, the others offered as ``viewpoints`` by name; its light (``framing.light_of``) or a soft one from the
    front; without a camera, framed from inside an interior or from where a figure faces. Builds the
    scene's tree (which the framing reads, and painting needs anyway)."""
    parts = model.parts
    objects = [SceneObject(f"{title}#{k}", p, [(np.eye(4), p)]) for k, p in enumerate(parts)]
    light = Light(
        tuple(np.array(framing.DEFAULT_LIGHT) / np.linalg.norm(framing.DEFAULT_LIGHT)), framing.DEFAULT_AMBIENT
    )
    scene = Scene(name, title, frame_camera(parts), Environment.constant((0.62, 0.68, 0.78)), light, objects)
    geometry, tracer = scene.geometry(0.0)
    release_freed_memory()  # building the tree freed as much again as it keeps
    scene.light = framing.light_of(model.lights, geometry) if model.lights else framing.default_light(geometry)
    cameras = framed_viewpoints(model.viewpoints, geometry, tracer, title)
    scene.camera = cameras.pop(next(iter(cameras))) if cameras else framing.default_camera(geometry, tracer)
    scene.viewpoints = cameras  # the others, offered by name
    scene.motions = dict(zip(_unique([m.name for m in model.motions]), model.motions, strict=True))
    return scene


def framed_viewpoints(viewpoints, geometry, tracer, title: str) -> dict[str, Camera]:
    """A model's cameras by (unique) name, in its order; a camera that cannot frame the scene (far away, scaled
    huge, its up along its view) is left out, said in one line, and the scene falls back on its framed view."""
    cameras = {}
    for name, viewpoint in zip(_unique([v.name for v in viewpoints]), viewpoints, strict=True):
        try:
            cameras[name] = framing.viewpoint_camera(viewpoint, geometry, tracer)
        except (CameraError, ValueError, FloatingPointError) as exc:
            log.info("%s: camera %r skipped: %s", title, name[:80], str(exc).splitlines()[0] if str(exc) else exc)
    return cameras


def scene_names(folder: Path = SCENES_DIR) -> list[str]:
    return sorted(p.stem for p in Path(folder).glob("*.toml") if SCENE_NAME.fullmatch(p.stem))


def load_scene(ref: str, folder: Path = SCENES_DIR) -> Scene:
    """A scene by name (from ``folder``), by scene file path (``.toml``), or by mesh file path."""
    if SCENE_NAME.fullmatch(ref) and (Path(folder) / f"{ref}.toml").is_file():
        return load_scene_file(Path(folder) / f"{ref}.toml", ref)
    path = Path(ref)
    if path.suffix.lower() == ".toml":
        return load_scene_file(path)
    if path.is_file():
        return mesh_scene(path)
    known = ", ".join(scene_names(folder)) or "none"
    raise SceneError(f"unknown scene {ref!r}: not a scene name (known: {known}) nor an existing file")

"""How to paint: the painting settings, declared once and validated at construction.

Each field of :class:`PaintParams` declares its default, a line of help and its bounds (:func:`setting`).
Everything else that names a painting setting is derived from :data:`PAINT_SETTINGS`: the wire model
(``service/protocol.py``), the options of ``rcp render`` (``cli.py``) and the client's defaults (the
generated ``client/protocol.js``). A new setting is one new field; ``tests/service/test_params.py`` fails
until it reaches every caller. A frozen dataclass, not a pydantic model: ``dataclasses.replace`` validates (an
override is a ``replace``), the engine keeps its one-line errors, and the wire adds only what it needs
(every field optional, ``null`` for the scene's value).
"""

from __future__ import annotations

import math
import numbers
import pickle
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any, get_args, get_type_hints

import numpy as np

from ..camera.camera import Camera
from .mappings import BUILT_IN, MAPPINGS, get_mapping, register_mapping

METHODS = ("raytrace", "image")
"""How later iterations see their displaced targets: traced (right everywhere), or looked up in the plain
render (``imagespace.py``: fast, needs ``lambda_e = 0``, wrong off screen)."""
Overrides = tuple[tuple[str, tuple[tuple[str, Any], ...]], ...]
"""Settings per object or per material, frozen: ``((name, ((setting, value), ...)), ...)``, sorted."""
EDGES = ("clamp", "wrap", "mirror")
"""How the image method reads a lookup that falls off screen (the order is the kernel's code for each)."""


def setting(default, help: str, **bounds) -> Any:
    """A field of :class:`PaintParams`: the engine's default, one line of help (for ``rcp render --help``,
    the wire schema and the client) and the bounds, keyword arguments of :class:`PaintSetting`."""
    return field(default=default, metadata={"help": help, **bounds})


@dataclass(frozen=True)
class PaintParams:
    """How to paint. ``lambda_p`` in pixels, ``lambda_e`` in scene units; ``z0`` (focus depth) defaults to
    the distance from the eye to ``look_at``; ``z_max`` (depth of a miss) to the scene's size.
    ``method`` is one of :data:`METHODS`; ``edge`` (one of :data:`EDGES`) is how the image method reads
    off screen. ``objects`` and ``materials`` hold settings per object and per material of the scene, by
    name (:data:`Overrides`, only :data:`PER_PIXEL` settings): a pixel paints by those of the object and
    material it showed in ``I_{n-1}`` (:meth:`overridden`; ``fields.Looks``).

    One set of bounds serves the engine, the wire and the command line: they keep numbers sane (finite,
    the right sign, nothing a painting cannot mean), not cost. ``lambda_p`` reaches 1e6 pixels because the
    engine paints that far in the stability study and stays finite; ``iterations`` and ``spp`` reach what
    an offline still may want. What a painting may cost is the service's limit (``RCP_MAX_WORK``: pixels x
    spp x iterations), not a bound of one setting.
    """

    mapping: str = setting("color", "target displacement mapping", choices=BUILT_IN, lookup=get_mapping)
    eye_mapping: str = setting("color", "eye displacement mapping", choices=BUILT_IN, lookup=get_mapping)
    iterations: int = setting(6, "recursion depth N", ge=1, le=256)
    spp: int = setting(1, "samples per pixel, stratified and seeded", ge=1, le=1024)
    lambda_p: float = setting(8.0, "largest target displacement, in pixels", ge=-1e6, le=1e6)
    lambda_e: float = setting(0.0, "largest eye displacement, in scene units", ge=-100, le=100)
    z0: float | None = setting(
        None, "focus depth of the depth mapping (default: the distance to look-at)", gt=0, le=1e6
    )
    noise: float = setting(0.0, "screen noise: strength of a seeded random vector added per pixel", ge=0, le=16)
    surface_noise: float = setting(
        0.0,
        "surface noise: strength of a seeded random vector that belongs to the world point a pixel saw",
        ge=0,
        le=16,
    )
    surface_scale: float = setting(
        0.0, "surface noise that scales the displacement: D times (1 + this x a value in [-1, 1])", ge=0, le=16
    )
    grain: float = setting(0.05, "size of the surface noise's cells, in scene units", gt=0, le=1e6)
    hatch: bool = setting(
        False, "surface noise coherent along the smudge (constant along the displacement, varying across: hatch lines)"
    )
    seed: int = setting(0, "seed of the jitter and the noise", ge=0, le=2**31 - 1)
    boil: int = setting(
        0,
        "boil: a film (and a walk while it moves) reseeds its jitter and noise every this many frames, a tremble "
        "(0: never)",
        ge=0,
        le=10_000,
    )
    z_max: float | None = setting(None, "depth recorded for a miss (default: beyond the scene)", gt=0, le=1e6)
    method: str = setting(
        "raytrace",
        "raytrace (right everywhere) or image (look up the plain render: fast, needs lambda_e 0)",
        choices=METHODS,
    )
    edge: str = setting("mirror", "how the image method reads off screen", choices=EDGES)
    objects: Overrides = field(default=(), metadata={"per": "object"})
    materials: Overrides = field(default=(), metadata={"per": "material"})

    def __post_init__(self):
        for declared in PAINT_SETTINGS.values():
            declared.check(getattr(self, declared.name))
        for per in PER:
            object.__setattr__(self, per, overrides(per, getattr(self, per)))
        if self.method == "image" and any(p.lambda_e != 0.0 for p in self.looks()):
            raise ValueError(
                f"the image-space method cannot represent eye displacement (lambda_e = {self.lambda_e}): "
                "use lambda_e 0, or method raytrace"
            )

    @classmethod
    def from_dict(cls, values: dict) -> PaintParams:
        """Settings by name (a scene file's ``[paint]`` table, ``objects`` and ``materials`` among them: name ->
        settings); an unknown name is refused with the known ones."""
        unknown = set(values) - set(PAINT_SETTINGS) - set(PER)
        if unknown:
            raise ValueError(f"unknown paint settings {sorted(unknown)}; known: {sorted(PAINT_SETTINGS)}")
        return cls(**values)

    def non_defaults(self) -> dict:
        """The settings that differ from the engine's defaults, name -> value (what a scene changes); the
        overrides per object and per material as ``{name: {setting: value}}``."""
        changed = {name: value for name, s in PAINT_SETTINGS.items() if (value := getattr(self, name)) != s.default}
        return changed | {per: as_dict(table) for per in PER if (table := getattr(self, per))}

    def __reduce__(self):
        """Pickled with the registered mappings it paints with (a built-in one travels by name): a painting
        sent to another process (a Ray worker) paints there as here, though nobody registered them there."""
        names = {name for look in self.looks() for name in (look.mapping, look.eye_mapping)}
        carried = tuple(_by_value(get_mapping(name)) for name in sorted(names) if name not in BUILT_IN)
        return _unpickled, (self.settings(), carried)

    def settings(self) -> dict[str, Any]:
        """Every setting by name, the overrides per object and per material as ``{name: {setting: value}}``."""
        return {name: getattr(self, name) for name in PAINT_SETTINGS} | {
            per: as_dict(getattr(self, per)) for per in PER
        }

    def overridden(self, object: str | None, material: str | None) -> PaintParams:
        """The painting of a pixel that shows ``object`` made of ``material`` (None: a miss, or no name):
        these settings, then the material's overrides, then the object's (the more particular wins)."""
        given = {**dict(dict(self.materials).get(material or "", ())), **dict(dict(self.objects).get(object or "", ()))}
        return replace(self, objects=(), materials=(), **given) if given else self

    def looks(self) -> list[PaintParams]:
        """This painting and each of its overrides (what any pixel may paint with)."""
        return [self, *(self.overridden(name, None) for name, _ in self.objects)] + [
            self.overridden(None, name) for name, _ in self.materials
        ]

    def at_scale(self, scale: float) -> PaintParams:
        """The same painting at ``scale`` times the pixels a side (a walk frame of a larger canvas): ``lambda_p``
        counts pixels, so it scales with them, its overrides' too, and the smudges keep their size in the
        picture."""
        if scale == 1.0:
            return self

        def scaled(table: Overrides) -> Overrides:
            return tuple(
                (name, tuple((key, value * scale if key == "lambda_p" else value) for key, value in settings))
                for name, settings in table
            )

        return replace(
            self, lambda_p=self.lambda_p * scale, objects=scaled(self.objects), materials=scaled(self.materials)
        )

    def focus(self, camera: Camera) -> float:
        """``z0``: the focus depth given, or the view depth of the camera's look-at point."""
        return self.z0 if self.z0 is not None else float(np.linalg.norm(np.subtract(camera.look_at, camera.eye)))

    def reads(self) -> frozenset[str]:
        """The channels of ``I_{n-1}`` this painting reads (the only ones it records): its mappings', the
        object or material a pixel showed where settings vary by them, the world point for surface noise."""
        channels = frozenset({"object"} if self.objects else ()) | ({"material"} if self.materials else set())
        for look in self.looks():
            channels |= get_mapping(look.mapping).reads
            if look.lambda_e != 0.0:
                channels |= get_mapping(look.eye_mapping).reads
            if look.surface_noise or look.surface_scale:
                channels |= {"position", "normal"} if look.hatch else {"position"}
        return channels


def _by_value(mapping) -> bytes:
    """A registered mapping pickled with its function's code (``ray.cloudpickle``, the cloudpickle that Ray ships
    inside itself: the ``cluster`` extra declares Ray, not cloudpickle), not a reference to the module that
    defined it: a Ray worker need not be able to import a script's or a test's module."""
    try:
        from ray import cloudpickle
    except ImportError:  # no Ray: nothing sends this to a Ray worker, and a process of ours imports it by reference
        return pickle.dumps(mapping)
    module = sys.modules.get(mapping.field.__module__)
    if module is None or module.__name__ == "__main__":  # cloudpickle sends those by value anyway
        return cloudpickle.dumps(mapping)
    cloudpickle.register_pickle_by_value(module)
    try:
        return cloudpickle.dumps(mapping)
    finally:
        cloudpickle.unregister_pickle_by_value(module)


def _unpickled(settings: dict[str, Any], carried: tuple[bytes, ...]) -> PaintParams:
    """A pickled :class:`PaintParams` again, its registered mappings registered here first (if this process
    does not know them by those names)."""
    for mapping in map(pickle.loads, carried):
        if mapping.name not in MAPPINGS:
            register_mapping(mapping.name, mapping.reads, mapping.field)
    return PaintParams(**settings)


@dataclass(frozen=True)
class PaintSetting:
    """One painting setting as declared: ``kind`` is bool, int, float or str; ``optional``: None is a value (it
    means "derive it", as the help says). Numbers are finite and within ``ge``/``gt``/``le``; a name is
    one of ``choices``, or, with ``lookup``, whatever the registry knows (mappings are registered at run
    time; ``choices`` are then the built-in ones, those every server and command line offer)."""

    name: str
    kind: type
    optional: bool
    default: Any
    help: str
    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    choices: tuple[str, ...] = ()
    lookup: Callable[[str], object] | None = None

    def check(self, value) -> None:
        """Raises ``ValueError``, one line naming the setting, unless ``value`` is one this setting takes."""
        if value is None:
            if self.optional:
                return
            raise ValueError(f"{self.name} must be given")
        if self.kind is str:
            if not isinstance(value, str):
                raise ValueError(f"{self.name} must be a name, got {value!r}")
            if self.lookup is not None:
                try:
                    self.lookup(value)
                except ValueError as exc:
                    raise ValueError(f"{self.name}: {exc}") from None
            elif value not in self.choices:
                raise ValueError(f"unknown {self.name} {value!r}; choose one of {', '.join(self.choices)}")
            return
        if self.kind is bool:
            if not isinstance(value, bool):
                raise ValueError(f"{self.name} must be true or false, got {value!r}")
            return
        whole = self.kind is int
        if isinstance(value, bool) or not isinstance(value, numbers.Integral if whole else numbers.Real):
            raise ValueError(f"{self.name} must be a {'whole ' if whole else ''}number, got {value!r}")
        number = float(value)  # for the comparisons (the messages show the value as given)
        if not math.isfinite(number):
            raise ValueError(f"{self.name} must be a finite number, got {value}")
        if self.ge is not None and number < self.ge:
            raise ValueError(f"{self.name} must be at least {self.ge}, got {value}")
        if self.gt is not None and number <= self.gt:
            raise ValueError(f"{self.name} must be more than {self.gt}, got {value}")
        if self.le is not None and number > self.le:
            raise ValueError(f"{self.name} must be at most {self.le}, got {value}")


PER = ("objects", "materials")
"""The fields of :class:`PaintParams` that hold settings per object and per material: name -> settings."""

PER_PIXEL = (
    "mapping",
    "eye_mapping",
    "lambda_p",
    "lambda_e",
    "noise",
    "surface_noise",
    "surface_scale",
    "grain",
    "hatch",
)
"""The settings an object or a material may set for itself: those that can vary from pixel to pixel."""


def overrides(per: str, table) -> Overrides:
    """``table`` (name -> settings, as a dict or as :data:`Overrides`) checked and frozen: every setting one of
    :data:`PER_PIXEL` and valid; refused in one line naming the object or material otherwise."""
    items = table.items() if isinstance(table, Mapping) else table
    frozen = []
    for name, settings in items:
        if not isinstance(name, str) or not isinstance(settings, Mapping | tuple):
            raise ValueError(f"{per}: give each a name and a table of settings, got {name!r}")
        values = dict(settings)
        unknown = set(values) - set(PER_PIXEL)
        if unknown:
            raise ValueError(
                f"{per}.{name}: {', '.join(sorted(map(str, unknown)))} cannot vary per pixel; these can: "
                f"{', '.join(PER_PIXEL)}"
            )
        for key, value in values.items():
            try:
                PAINT_SETTINGS[key].check(value)
            except ValueError as exc:
                raise ValueError(f"{per}.{name}: {exc}") from None
        frozen.append((name, tuple(sorted(values.items()))))
    return tuple(sorted(frozen))


def as_dict(table: Overrides) -> dict[str, dict[str, Any]]:
    """:data:`Overrides` as plain data: name -> {setting: value}."""
    return {name: dict(settings) for name, settings in table}


def _declared() -> dict[str, PaintSetting]:
    hints = get_type_hints(PaintParams)
    declared = {}
    for f in fields(PaintParams):
        if f.name in PER:
            continue
        kinds = get_args(hints[f.name]) or (hints[f.name],)
        kind = next(k for k in kinds if k is not type(None))
        declared[f.name] = PaintSetting(f.name, kind, type(None) in kinds, f.default, **f.metadata)
    return declared


PAINT_SETTINGS: dict[str, PaintSetting] = _declared()
"""Every painting setting, in the order of :class:`PaintParams`' fields: name -> its declaration."""

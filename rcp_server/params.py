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
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any, get_args, get_type_hints

import numpy as np

from .camera import Camera
from .mappings import BUILT_IN, get_mapping

METHODS = ("raytrace", "image")
"""How later iterations see their displaced targets: traced (right everywhere), or looked up in the plain
render (``imagespace.py``: fast, needs ``lambda_e = 0``, wrong off screen)."""
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
    off screen.

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
    noise: float = setting(0.0, "strength of a seeded random vector added per pixel", ge=0, le=16)
    seed: int = setting(0, "seed of the jitter and the noise", ge=0, le=2**31 - 1)
    z_max: float | None = setting(None, "depth recorded for a miss (default: beyond the scene)", gt=0, le=1e6)
    method: str = setting(
        "raytrace",
        "raytrace (right everywhere) or image (look up the plain render: fast, needs lambda_e 0)",
        choices=METHODS,
    )
    edge: str = setting("mirror", "how the image method reads off screen", choices=EDGES)
    fast: bool = setting(
        True,
        "shortcuts: skip the BVH where the plain render knows the hit, keep pixels whose inputs did not change "
        "(off: trace every ray of every iteration)",
    )

    def __post_init__(self):
        for declared in PAINT_SETTINGS.values():
            declared.check(getattr(self, declared.name))
        if self.method == "image" and self.lambda_e != 0.0:
            raise ValueError(
                f"the image-space method cannot represent eye displacement (lambda_e = {self.lambda_e}): "
                "use lambda_e 0, or method raytrace"
            )

    @classmethod
    def from_dict(cls, values: dict) -> PaintParams:
        """Settings by name (a scene file's ``[paint]`` table); an unknown name is refused with the known ones."""
        unknown = set(values) - set(PAINT_SETTINGS)
        if unknown:
            raise ValueError(f"unknown paint settings {sorted(unknown)}; known: {sorted(PAINT_SETTINGS)}")
        return cls(**values)

    def non_defaults(self) -> dict:
        """The settings that differ from the engine's defaults, name -> value (what a scene changes)."""
        return {name: value for name, s in PAINT_SETTINGS.items() if (value := getattr(self, name)) != s.default}

    def focus(self, camera: Camera) -> float:
        """``z0``: the focus depth given, or the view depth of the camera's look-at point."""
        return self.z0 if self.z0 is not None else float(np.linalg.norm(np.subtract(camera.look_at, camera.eye)))

    def reads(self) -> frozenset[str]:
        """The channels of ``I_{n-1}`` this painting reads (the only ones it records)."""
        channels = get_mapping(self.mapping).reads
        if self.lambda_e != 0.0:
            channels |= get_mapping(self.eye_mapping).reads
        return channels


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


def _declared() -> dict[str, PaintSetting]:
    hints = get_type_hints(PaintParams)
    declared = {}
    for f in fields(PaintParams):
        kinds = get_args(hints[f.name]) or (hints[f.name],)
        kind = next(k for k in kinds if k is not type(None))
        declared[f.name] = PaintSetting(f.name, kind, type(None) in kinds, f.default, **f.metadata)
    return declared


PAINT_SETTINGS: dict[str, PaintSetting] = _declared()
"""Every painting setting, in the order of :class:`PaintParams`' fields: name -> its declaration."""

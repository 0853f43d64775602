"""The hot passes of an iteration, compiled (numba): numpy cannot fuse them.

``cast.py``: camera assignment (``cast_rays``, with the built-in mappings fused in, and ``fill_field``;
``cast_rays`` picks ``cast_flat`` or ``cast_general``, from Python);
``shade.py``: hits -> per-pixel data (``shade``); ``triangle.py``: where a ray meets the triangle it hits
(``place_hits``); ``iterate.py``: one traced iteration of a tile, the steps above called in turn
(``paint_iteration``); ``alpha.py``: rays through cut-outs (``pass_masked``); ``lookup.py``: the
image-space method's lookup (``look_up``); ``visibility.py``: the faces of rays from eyes at rest, from
the screen cells of ``screencells.py`` where they prove Embree's answer (``find_faces``); ``embree.py``: the
binding to Embree's C API that the others call (``intersect_rays``). Each releases the GIL, so tiles run on
threads side by side, and each has a plain numpy reference in ``tests/engine`` that it is checked against.
``prefetch.py`` is a helper of theirs: a hint that brings a cache line in before a later loop reads it.

Call them by keyword, with the bundles of ``bundles.py``: two arrays of the same type passed in each
other's place must be an error, not a wrong image.
"""

from .alpha import masked_rays, pass_masked
from .bundles import (
    NO_SCREEN,
    Cast,
    Channels,
    Field,
    ImagePlane,
    Ink,
    Materials,
    Records,
    Scratch,
    Screen,
    Seen,
    Shading,
    Surfaces,
    Trace,
    channels,
    or_dummy,
    records,
)
from .cast import FIELD_COLOR, FIELD_DEPTH, FIELD_GIVEN, FIELD_NORMAL, FIELD_ZERO, cast_rays, fill_field
from .iterate import paint_iteration
from .lookup import EDGE_CLAMP, EDGE_MIRROR, EDGE_WRAP, look_up
from .shade import record_surfaces, shade
from .triangle import place_hits
from .visibility import find_faces

__all__ = [
    "EDGE_CLAMP",
    "EDGE_MIRROR",
    "EDGE_WRAP",
    "FIELD_COLOR",
    "FIELD_DEPTH",
    "FIELD_GIVEN",
    "FIELD_NORMAL",
    "FIELD_ZERO",
    "Cast",
    "Channels",
    "Field",
    "ImagePlane",
    "Ink",
    "Materials",
    "NO_SCREEN",
    "Records",
    "Scratch",
    "Screen",
    "Seen",
    "Shading",
    "Surfaces",
    "Trace",
    "cast_rays",
    "channels",
    "fill_field",
    "find_faces",
    "look_up",
    "masked_rays",
    "or_dummy",
    "paint_iteration",
    "pass_masked",
    "place_hits",
    "record_surfaces",
    "records",
    "shade",
]

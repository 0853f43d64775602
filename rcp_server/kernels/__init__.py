"""The hot passes of an iteration, fused and compiled (numba): numpy cannot fuse them.

``cast.py``: camera assignment (``cast_rays``, with the built-in mappings fused in, and ``fill_field``);
``shade.py``: Embree's hits -> per-pixel data (``shade``); ``lookup.py``: the image-space method's
lookup (``look_up``). Each releases the GIL, so tiles run on threads side by side with Embree, and each
has a plain numpy reference in ``tests/engine`` that it is checked against.

Call them by keyword, with the bundles of ``bundles.py``: two arrays of the same type passed in each
other's place must be an error, not a wrong image.
"""

from .bundles import Channels, Field, ImagePlane, Surfaces, channels, or_dummy
from .cast import FIELD_COLOR, FIELD_DEPTH, FIELD_GIVEN, FIELD_NORMAL, FIELD_ZERO, cast_rays, fill_field
from .lookup import EDGE_CLAMP, EDGE_MIRROR, EDGE_WRAP, look_up
from .shade import shade

__all__ = [
    "EDGE_CLAMP",
    "EDGE_MIRROR",
    "EDGE_WRAP",
    "FIELD_COLOR",
    "FIELD_DEPTH",
    "FIELD_GIVEN",
    "FIELD_NORMAL",
    "FIELD_ZERO",
    "Channels",
    "Field",
    "ImagePlane",
    "Surfaces",
    "cast_rays",
    "channels",
    "fill_field",
    "look_up",
    "or_dummy",
    "shade",
]

"""The hot passes of an iteration, fused and compiled (numba): numpy cannot fuse them.

``cast.py``: camera assignment (``cast_rays``, with the built-in mappings fused in, and ``fill_field``);
``shade.py``: hits -> per-pixel data (``shade``); ``triangle.py``: where a ray meets the triangle it hits
(``place_hits``); ``lookup.py``: the image-space method's lookup (``look_up``); ``seen.py`` and
``reuse.py``: the shortcuts of the ``fast`` setting (``resolve_seen`` finds the hit where the plain render
already knows it, ``changed_pixels`` what must be painted again); ``alpha.py``: which hits land on a cut-out
(``masked_rays``, for ``alphamask.py``). Each releases the GIL, so tiles run on threads side by side with
Embree, and each has a plain numpy reference in ``tests/engine`` that it is checked against.

Call them by keyword, with the bundles of ``bundles.py``: two arrays of the same type passed in each
other's place must be an error, not a wrong image.
"""

from .alpha import masked_rays
from .bundles import Channels, Field, ImagePlane, Seen, Surfaces, channels, or_dummy
from .cast import FIELD_COLOR, FIELD_DEPTH, FIELD_GIVEN, FIELD_NORMAL, FIELD_ZERO, cast_rays, fill_field
from .lookup import EDGE_CLAMP, EDGE_MIRROR, EDGE_WRAP, look_up
from .reuse import DISPLAY_LEVELS, changed_pixels
from .seen import resolve_seen
from .shade import shade
from .triangle import place_hits

__all__ = [
    "DISPLAY_LEVELS",
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
    "Seen",
    "Surfaces",
    "cast_rays",
    "changed_pixels",
    "channels",
    "fill_field",
    "look_up",
    "masked_rays",
    "or_dummy",
    "place_hits",
    "resolve_seen",
    "shade",
]

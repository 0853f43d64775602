"""One router per surface: ``rest`` (``/api``) and ``walk`` (the ``/ws`` walk-through)."""

from typing import Any

Responses = dict[int | str, dict[str, Any]]
"""A route's documented answers besides its own, as FastAPI's ``responses`` takes them."""

SCENE_BODY: Responses = {  # what every route that takes a JSON body naming a scene may answer besides its own
    400: {"description": "a body that is not JSON text at all (not UTF-8, or nested too deep)"},
    404: {"description": "no such scene"},
    413: {"description": "the body is larger than RCP_MAX_BODY_BYTES"},
}

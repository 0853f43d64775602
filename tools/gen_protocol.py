"""Write ``client/protocol.js`` from the wire models (``rcp_server/service/protocol.py``): the browser's side of
the protocol, generated so that the two sides cannot drift apart (``tests/service/test_protocol.py`` checks that
the committed file is what this prints).

    python tools/gen_protocol.py > client/protocol.js

The module holds, each once: a JSDoc type for every WebSocket message both ways (for ``// @ts-check`` and the
editor), the JSON schema of a camera (``CAMERA``, with the bounds the server takes) and of the painting settings
(``PAINT``), the schema of each message the client sends (``CLIENT``, written over those two where it repeats
them), and the engine's painting defaults (``ENGINE_DEFAULTS``), for the settings a scene leaves out.
"""

from __future__ import annotations

import json
from typing import Any

from rcp_server.service.protocol import schemas
from rcp_server.settings.params import PaintParams

COMMAND = "python tools/gen_protocol.py > client/protocol.js"


class Js:
    """A JavaScript expression in the generated module: a constant's name, or an object spread over one."""

    def __init__(self, base: str, changes: dict[str, Any] | None = None):
        self.base, self.changes = base, changes


def shared(value: Any, base: Any, name: str) -> Any:
    """``value`` with whatever equals ``base`` written as a reference to the constant ``name`` that holds it: all
    of it, or an object spread over it with the keys that differ (``{...PAINT, "title": "PaintMessage"}``)."""
    if value == base:
        return Js(name)
    if isinstance(value, dict) and isinstance(base, dict) and base.keys() <= value.keys():
        changes = {k: shared(v, base.get(k), f"{name}[{json.dumps(k)}]") for k, v in value.items() if v != base.get(k)}
        return Js(name, changes)
    return value


def js(value: Any, indent: int = 0) -> str:
    """``value`` as JavaScript: JSON (``indent=1``, sorted keys), with :class:`Js` expressions in place."""
    pad, inner = " " * indent, " " * (indent + 1)
    if isinstance(value, Js):
        if value.changes is None:
            return value.base
        entries = [f"...{value.base}"] + [
            f"{json.dumps(k)}: {js(v, indent + 1)}" for k, v in sorted(value.changes.items())
        ]
        return "{\n" + ",\n".join(inner + e for e in entries) + "\n" + pad + "}"
    if isinstance(value, dict) and value:
        entries = [f"{json.dumps(k)}: {js(v, indent + 1)}" for k, v in sorted(value.items())]
        return "{\n" + ",\n".join(inner + e for e in entries) + "\n" + pad + "}"
    if isinstance(value, list) and value:
        return "[\n" + ",\n".join(inner + js(v, indent + 1) for v in value) + "\n" + pad + "]"
    return json.dumps(value)


# ---- JSDoc types ----

RENAMED = {"Error": "ErrorMessage", "CameraSpec": "Camera"}  # not the built-in Error; a camera is a Camera


def type_name(title: str) -> str:
    return RENAMED.get(title, title)


def ts_type(schema: dict) -> str:
    """The TypeScript type (as JSDoc writes it) of a JSON schema."""
    if "$ref" in schema:
        return type_name(schema["$ref"].rsplit("/", 1)[-1])
    if "const" in schema:
        return json.dumps(schema["const"])
    if "enum" in schema:
        return " | ".join(json.dumps(v) for v in schema["enum"])
    if "anyOf" in schema:
        return " | ".join(ts_type(s) for s in schema["anyOf"])
    kind = schema.get("type")
    if kind in ("integer", "number"):
        return "number"
    if kind in ("string", "boolean", "null"):
        return kind
    if kind == "array":
        if "prefixItems" in schema:
            return "[" + ", ".join(ts_type(s) for s in schema["prefixItems"]) + "]"
        return f"Array<{ts_type(schema['items'])}>" if "items" in schema else "Array<any>"
    if kind == "object":
        values = schema.get("additionalProperties")
        return f"Object<string, {ts_type(values)}>" if isinstance(values, dict) else "Object<string, any>"
    return "any"


def typedef(name: str, schema: dict, every_field: bool) -> str:
    """One ``@typedef`` with a ``@property`` per field; optional fields in brackets (``every_field``: none is, as
    the server sends every field of its messages)."""
    required = set(schema.get("required", ()))
    lines = ["/**"]
    lines += [f" * {line}".rstrip() for line in schema.get("description", "").replace("``", "`").splitlines()]
    lines.append(f" * @typedef {{object}} {name}")
    for field, sub in schema.get("properties", {}).items():
        label = field if every_field or field in required else f"[{field}]"
        about = sub.get("description", "").replace("``", "`").replace("\n", " ")
        lines.append(f" * @property {{{ts_type(sub)}}} {label}" + (f" - {about}" if about else ""))
    lines.append(" */")
    return "\n".join(lines)


def typedefs(every: dict[str, Any]) -> str:
    """The types of every message, of the models inside them, and the two unions of each side."""
    out, seen = [typedef("Camera", every["camera"], every_field=False)], {"CameraSpec"}
    for side, every_field in (("client", False), ("server", True)):
        for schema in every[side].values():
            for name, sub in schema.get("$defs", {}).items():
                if name not in seen:
                    seen.add(name)
                    out.append(typedef(type_name(name), sub, every_field))
            out.append(typedef(type_name(schema["title"]), schema, every_field))
        union = " | ".join(type_name(s["title"]) for s in every[side].values())
        out.append(f"/** @typedef {{{union}}} {side.capitalize()}Message */")
    return "\n".join(out)


# ---- the module ----


def client_module() -> str:
    """``client/protocol.js``. The painting settings' schemas are written once (``PAINT_PROPERTIES``) and referenced
    wherever a schema holds them again: the settings an object or material may set (``PAINT.$defs.OwnPaintModel``)
    and the ``paint`` message; the camera message is ``CAMERA`` with its ``type`` and ``id``."""
    every = schemas()
    paint, camera = every["paint"], every["camera"]
    properties = paint["properties"]
    own = paint["$defs"]["OwnPaintModel"]
    own_js = {
        **own,
        "properties": {
            k: Js(f"PAINT_PROPERTIES[{json.dumps(k)}]") if v == properties.get(k) else v
            for k, v in own["properties"].items()
        },
    }
    paint_js = {**paint, "$defs": {**paint["$defs"], "OwnPaintModel": own_js}, "properties": Js("PAINT_PROPERTIES")}
    client = {
        **every["client"],
        "paint": shared(every["client"]["paint"], paint, "PAINT"),
        "camera": shared(every["client"]["camera"], camera, "CAMERA"),
    }
    defaults = json.dumps(PaintParams().settings(), indent=1)
    return (
        "// @ts-check\n"
        f"// Generated by `{COMMAND}` from rcp_server/service/protocol.py; do not edit.\n\n"
        "// ---- the WebSocket's messages, both ways ----\n"
        f"{typedefs(every)}\n\n"
        "// ---- the JSON schemas the client checks against (messages.js, link.js, panel.js) ----\n"
        "// A camera, with the bounds the server takes.\n"
        f"export const CAMERA = {js(camera)};\n"
        "// The painting settings (rcp_server/settings/params.py), each once.\n"
        f"const PAINT_PROPERTIES = {js(properties)};\n"
        "// The painting settings of a request or a message; OwnPaintModel: those an object or a material may set.\n"
        f"export const PAINT = {js(paint_js)};\n"
        "// The messages the client sends, by type.\n"
        f"export const CLIENT = {js(client)};\n"
        "// The engine's painting settings (rcp_server/settings/params.py), for those a scene leaves out.\n"
        f"export const ENGINE_DEFAULTS = {defaults};\n"
    )


if __name__ == "__main__":
    print(client_module(), end="")

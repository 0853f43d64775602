"""The reference tables of the documentation, generated from the declarations when the site is built.

Every painting setting (``settings/params.py``: :data:`PAINT_SETTINGS`), camera field (``camera/camera.py``:
:data:`CAMERA_FIELDS`) and ``RCP_`` setting (``service/settings.py``: :class:`Settings`) is declared once, with its
default, bounds and help. A page says where a table goes with a line of its own, and this MkDocs hook
(``hooks:`` in ``mkdocs.yml``) writes the table there at build time, so a new setting appears on the next build
and nothing is copied by hand:

- ``<!-- reference: paint -->``: every painting setting;
- ``<!-- reference: camera -->``: every camera field;
- ``<!-- reference: environment -->``: every ``RCP_`` setting, or ``<!-- reference: environment max_videos ... -->``
  for those named (a guide page shows the limits of its subject);
- ``<!-- reference: websocket -->``: every WebSocket message both ways, from the same JSON schemas
  (``service/protocol.py``: :func:`schemas`) that ``tools/gen_protocol.py`` writes into the client.

``python docs/gen_reference.py`` prints the tables.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from types import UnionType
from typing import Any, get_args, get_origin

from pydantic.fields import FieldInfo

from rcp_server.camera.camera import CAMERA_FIELDS, CameraField
from rcp_server.service.protocol import schemas
from rcp_server.service.settings import REPOSITORY, Settings
from rcp_server.settings.params import PAINT_SETTINGS, PER_PIXEL, PaintSetting

MARKER = re.compile(r"^<!-- reference: (paint|camera|environment|websocket)((?: [a-z_]+)*) -->$", re.MULTILINE)
ENV_PREFIX = Settings.model_config.get("env_prefix", "")


def paint_table(settings: Iterable[PaintSetting], per_pixel: Iterable[str] = PER_PIXEL) -> str:
    """A Markdown table of painting settings: name (``rcp render``'s option is ``--`` and the name with dashes),
    default, bounds, whether objects and materials may set it, help."""
    per_pixel = set(per_pixel)
    rows = ["| setting | default | takes | per object | what |", "|---|---|---|---|---|"]
    for s in settings:
        takes = _names(s.choices) + (" or a registered mapping" if s.lookup is not None else "")
        if not s.choices:
            takes = _bounds(s.kind.__name__, ge=s.ge, gt=s.gt, le=s.le)
        if s.optional:
            takes += ", or null (derived)"
        per = "yes" if s.name in per_pixel else ""
        rows.append(f"| `{s.name}` | {_value(s.default)} | {takes} | {per} | {cell(s.help)} |")
    return "\n".join(rows)


def camera_table(fields: Iterable[CameraField]) -> str:
    """A Markdown table of camera fields: name, default, bounds, help."""
    rows = ["| field | default | takes | what |", "|---|---|---|---|"]
    for f in fields:
        kind = "3 numbers" if f.kind == "vec3" else getattr(f.kind, "__name__", str(f.kind))
        takes = _names(f.choices) if f.choices else _bounds(kind, ge=f.ge, gt=f.gt, lt=f.lt)
        default = "required" if f.required else _value(f.default)
        rows.append(f"| `{f.name}` | {default} | {takes} | {cell(f.help)} |")
    return "\n".join(rows)


def environment_table(fields: Mapping[str, FieldInfo], names: Iterable[str] | None = None) -> str:
    """A Markdown table of ``RCP_`` settings (all of ``fields``, or those ``names``): variable, default, what."""
    chosen = list(fields) if names is None else list(names)
    unknown = [name for name in chosen if name not in fields]
    if unknown:
        raise ValueError(f"no RCP_ setting named {', '.join(unknown)}")
    rows = ["| variable | default | takes | what |", "|---|---|---|---|"]
    for name in chosen:
        info = fields[name]
        if info.default_factory is not None:
            default = f"computed: `{getattr(info.default_factory, '__name__', 'factory')}()`"
        else:
            default = _value(info.default, name=name)
        bounds = {k: getattr(m, k) for m in info.metadata for k in ("ge", "gt", "le", "lt") if hasattr(m, k)}
        takes = _bounds(_kind(info.annotation), name=name, **bounds)
        rows.append(f"| `{ENV_PREFIX}{name.upper()}` | {default} | {takes} | {cell(info.description or '')} |")
    return "\n".join(rows)


SIDES = {
    "client": ("Client to server", "A field left out takes its default; a message that does not fit gets an `error`."),
    "server": ("Server to client", "Every field is sent."),
}


def websocket_reference(every: Mapping[str, Any]) -> str:
    """A section per side and a table per message: field, what it takes, its default, what it is."""
    out = []
    for side, (title, note) in SIDES.items():
        out += [f"## {title}", "", note, ""]
        for kind, schema in every[side].items():
            out += [f"### `{kind}`", "", _sentence(schema.get("description", "")), ""]
            required = set(schema.get("required", ()))
            rows = ["| field | takes | default | what |", "|---|---|---|---|"]
            for name, field in schema["properties"].items():
                if name == "type":
                    continue
                if side == "server" or name in required:
                    default = "required" if side == "client" else ""
                else:
                    default = _value(field.get("default"))
                about = field.get("description", "")
                rows.append(f"| `{name}` | {cell(_takes(field, schema))} | {default} | {cell(about)} |")
            out += [*rows, ""] if len(rows) > 2 else ["Only its `type`.", ""]
    return "\n".join(out).rstrip()


def _sentence(text: str) -> str:
    return " ".join(text.replace("``", "`").split())


def _takes(field: Mapping[str, Any], schema: Mapping[str, Any]) -> str:
    """What a JSON schema takes, as a reader says it: ``integer (>= 1, <= 4096)``, ``one of `a`, `b` ``."""
    if "$ref" in field:
        name = field["$ref"].rsplit("/", 1)[-1]
        return {"CameraSpec": "a camera", "OwnPaintModel": "painting settings"}.get(name, f"a {name}")
    if "const" in field:
        return f"`{field['const']}`"
    if "enum" in field:
        return "one of " + _names(field["enum"])
    if "anyOf" in field:
        kinds = [_takes(k, schema) for k in field["anyOf"]]
        return " or ".join(k for k in kinds if k != "null") + (" or null" if "null" in kinds else "")
    kind = field.get("type", "any value")
    if kind in ("integer", "number"):
        bounds = {k: field.get(v) for k, v in (("ge", "minimum"), ("gt", "exclusiveMinimum"), ("le", "maximum"))}
        return _bounds(kind, **bounds, lt=field.get("exclusiveMaximum"))
    if kind == "array":
        items = field.get("prefixItems")
        if items:
            first = items[0]
            bounds = {k: first.get(v) for k, v in (("ge", "minimum"), ("le", "maximum"))}
            return _bounds(f"{len(items)} numbers", **bounds) + (" each" if any(bounds.values()) else "")
        return f"a list of {_takes(field['items'], schema)}" if "items" in field else "a list"
    if kind == "object" and isinstance(field.get("additionalProperties"), dict):
        return f"a table of names to {_takes(field['additionalProperties'], schema)}"
    return {"object": "a table", "string": "text"}.get(kind, kind)


def expand(markdown: str) -> str:
    """``markdown`` with each reference marker replaced by its table, from the declarations as they are now."""

    def table(match: re.Match) -> str:
        kind, names = match.group(1), match.group(2).split()
        if kind == "paint":
            return paint_table(PAINT_SETTINGS.values())
        if kind == "camera":
            return camera_table(CAMERA_FIELDS.values())
        if kind == "websocket":
            return websocket_reference(schemas())
        return environment_table(Settings.model_fields, names or None)

    return MARKER.sub(table, markdown)


def on_page_markdown(markdown: str, **_: Any) -> str:
    """The MkDocs hook: every page's Markdown, markers expanded."""
    return expand(markdown)


# ---- formatting ----


def _value(value: Any, name: str = "") -> str:
    """A default or a bound as the tables show it: numbers plain (sizes in KiB, MiB, GiB; large powers of two as
    such), names and switches as code."""
    if value is None:
        return "none"
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    if isinstance(value, int) and name.endswith("_bytes") and value >= 1024:
        for unit, size in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
            if value % size == 0:
                return f"{value // size} {unit}"
    if isinstance(value, int) and value >= 1 << 16 and value & (value - 1) == 0:
        return f"2^{value.bit_length() - 1} ({value:,})"
    if isinstance(value, int):
        return f"{value:,}" if value >= 10_000 else str(value)
    if isinstance(value, float):
        return f"{value:g}".replace("e+0", "e").replace("e+", "e")
    if isinstance(value, Path):
        return (
            f"`{value.relative_to(REPOSITORY)}/` (in the repository)"
            if value.is_relative_to(REPOSITORY)
            else f"`{value}`"
        )
    if isinstance(value, tuple | list):
        return f"`{list(value)}`" if value else "none"
    return f"`{value}`"


def _bounds(kind: str, name: str = "", **bounds: float | None) -> str:
    words = {"ge": ">=", "gt": ">", "le": "<=", "lt": "<"}
    said = [f"{words[k]} {_value(v, name)}" for k, v in bounds.items() if v is not None]
    return kind + (f" ({', '.join(said)})" if said else "")


def _kind(annotation: Any) -> str:
    """``int``, ``str or none``, ``list``: a type as a reader says it."""
    kinds = get_args(annotation) if isinstance(annotation, UnionType) else (annotation,)
    said = [getattr(get_origin(k) or k, "__name__", str(k)) for k in kinds if k is not type(None)]
    return " or ".join(said) + (" or none" if type(None) in kinds else "")


def _names(choices: Iterable[str]) -> str:
    return ", ".join(f"`{c}`" for c in choices)


def cell(text: str) -> str:
    return text.replace("|", "\\|").replace("<", "&lt;").replace(">", "&gt;")


if __name__ == "__main__":
    print(paint_table(PAINT_SETTINGS.values()), camera_table(CAMERA_FIELDS.values()), sep="\n\n")
    print(environment_table(Settings.model_fields), websocket_reference(schemas()), sep="\n\n")

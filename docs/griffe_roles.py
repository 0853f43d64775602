"""A Griffe extension for the Python API page (``docs/api.md``): the docstrings name other objects the way Sphinx
does (``:class:`CameraError```, ``:attr:`PaintResult.state```), which Markdown would show as the role's
letters. This writes each such name as code, and as a link when it is one of ``rcp_server``'s public names (or
a member of one), so the page reads as the docstrings mean. ``mkdocs.yml`` loads it (``extensions:``)."""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:data|class|meth|func|attr|mod|exc|obj):`~?([A-Za-z_][\w.]*)`")
PUBLIC = frozenset(
    {
        "Camera",
        "MappingInput",
        "PaintParams",
        "PaintResult",
        "PaintState",
        "Region",
        "SceneError",
        "load_scene",
        "paint",
        "register_mapping",
    }
)


def plain(text: str) -> str:
    """``text`` with every Sphinx role written as Markdown: a public name links to its entry, others are code."""

    def name(match: re.Match) -> str:
        target = match.group(1)
        head = target.split(".")[0]
        return f"[`{target}`][rcp_server.{head}]" if head in PUBLIC else f"`{target}`"

    return ROLE.sub(name, text)


class SphinxRoles(griffe.Extension):
    """Rewrites the roles of every docstring Griffe reads."""

    def on_instance(self, *, obj: griffe.Object, **_: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = plain(obj.docstring.value)

"""The documentation: its reference is generated from the declarations (every painting setting, camera field and
``RCP_`` setting, and a new one as soon as it is declared), and the site builds with ``mkdocs build --strict``."""

import html
import importlib.util
import json
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
from pydantic import Field, create_model

import rcp_server
from rcp_server.camera.camera import CAMERA_FIELDS
from rcp_server.service.settings import Settings
from rcp_server.settings.params import PAINT_SETTINGS

ROOT = Path(__file__).resolve().parent.parent


def _generator(name: str = "gen_reference"):
    spec = importlib.util.spec_from_file_location(name, ROOT / "docs" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


gen = _generator()
figures = _generator("gen_figures")


def _first_column(table: str) -> list[str]:
    """The names in a generated table's first column, in order."""
    return re.findall(r"^\| `([^`]+)` \|", table, re.MULTILINE)


def test_the_reference_page_holds_every_declared_setting_field_and_variable():
    page = gen.expand((ROOT / "docs" / "reference.md").read_text())
    assert "<!-- reference:" not in page
    names = _first_column(page)
    expected = [*PAINT_SETTINGS, *CAMERA_FIELDS, *(f"RCP_{name.upper()}" for name in Settings.model_fields)]
    assert names == expected
    for declared in PAINT_SETTINGS.values():
        assert gen.cell(declared.help) in page
    for name, info in Settings.model_fields.items():
        assert info.description, f"RCP_{name.upper()} has no description to document"
        assert gen.cell(info.description) in page


def test_a_new_painting_setting_appears_in_the_reference():
    brush = replace(PAINT_SETTINGS["noise"], name="brush_size", help="the width of a brush, in pixels", le=64)
    table = gen.paint_table([*PAINT_SETTINGS.values(), brush])
    assert _first_column(table)[-1] == "brush_size"
    assert "| `brush_size` | 0 | float (>= 0, <= 64) |  | the width of a brush, in pixels |" in table


def test_a_new_camera_field_and_a_new_rcp_variable_appear_in_the_reference():
    roll = replace(CAMERA_FIELDS["fov"], name="roll", help="turn about the view, degrees", default=0.0, gt=-180)
    assert "| `roll` | 0 | float (> -180, < 180) | turn about the view, degrees |" in gen.camera_table([roll])
    wider = create_model("Wider", __base__=Settings, max_brushes=(int, Field(3, ge=1, description="brushes at once")))
    table = gen.environment_table(wider.model_fields)
    assert _first_column(table)[-1] == "RCP_MAX_BRUSHES"
    assert "| `RCP_MAX_BRUSHES` | 3 | int (>= 1) | brushes at once |" in table


def test_a_guide_page_names_only_variables_that_exist():
    with pytest.raises(ValueError, match="no RCP_ setting named max_brushes"):
        gen.expand("<!-- reference: environment max_pixels max_brushes -->")
    for page in (ROOT / "docs").rglob("*.md"):  # every marker in the pages expands
        assert "<!-- reference:" not in gen.expand(page.read_text()), page


def test_the_figures_pages_headline_tables_are_made_from_what_the_benchmarks_wrote(tmp_path):
    for name, header in (("accuracy", "| scene | method | spp |"), ("stability", "| probe | ray traced |")):
        page = figures.expand((ROOT / "docs" / "figures" / f"{name}.md").read_text())
        assert "<!-- figures:" not in page and header in page
    run = json.loads((ROOT / "docs" / "accuracy.json").read_text())
    table = figures.accuracy_table(run)
    for point in run["points"]:
        if point["scale"] == 1.0 and point["spp"] == 1:
            assert f"| `{point['scene']}` | {point['method']} | 1 | {point['ms']:.1f} | {point['psnr']:.2f} |" in table
    run["points"][0]["psnr"] = 99.0  # a new run of the benchmark, a new page
    (tmp_path / "accuracy.json").write_text(json.dumps(run))
    assert "| 99.00 |" in figures.expand("<!-- figures: accuracy -->", docs=tmp_path)


def test_every_figures_page_leads_with_its_figures_and_says_where_they_were_measured():
    """A headline table or chart first, then the command and the machine; nothing of how the project was built."""
    for page in (ROOT / "docs" / "figures").glob("*.md"):
        if page.name == "index.md":
            continue
        text = page.read_text()
        first = text.split("\n\n")[1]  # the block after the title
        assert first.startswith(("|", "<!-- figures:", "![")), page.name
        assert "`rcp bench " in text and re.search(r"\b\d+-core (?:AMD|Intel) \w+", text), page.name  # its machine
        said = re.search(r"\b(?:this|last|the|a) round\b|\btoday\b|\bbuilt on\b|build machine", text, re.IGNORECASE)
        assert said is None, f"{page.name}: {said and said.group(0)}"


def test_the_site_builds_strictly(tmp_path):
    """``mkdocs build --strict``: every link, anchor, included file and image resolves, the hook runs."""
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(ROOT), "NO_MKDOCS_2_WARNING": "1", "HOME": str(tmp_path)},
    )
    assert done.returncode == 0, done.stderr[-3000:]
    reference = (tmp_path / "site" / "reference" / "index.html").read_text()
    assert "RCP_MAX_WORK" in reference and "lambda_p" in reference and "look_at" in reference
    scene_files = (tmp_path / "site" / "guide" / "scene-files" / "index.html").read_text()
    assert "Still life" in scene_files  # examples/scene.toml, included
    assert (tmp_path / "site" / "gallery" / "default.jpg").is_file()
    api = (tmp_path / "site" / "api" / "index.html").read_text()  # every public name, from its docstring
    for name in rcp_server.__all__:
        assert f'id="rcp_server.{name}"' in api, name
        assert _first_line(getattr(rcp_server, name).__doc__) in html.unescape(re.sub(r"<[^>]+>", "", api)), name
    assert ":class:`" not in api and ":data:`" not in api  # Sphinx roles read as code or links


def test_the_websocket_page_holds_every_message_and_field_of_the_schemas():
    from rcp_server.service.protocol import schemas

    every = schemas()
    page = gen.expand((ROOT / "docs" / "websocket.md").read_text())
    assert "<!-- reference:" not in page
    headings = re.findall(r"^### `([a-z]+)`$", page, re.MULTILINE)
    assert headings == [*every["client"], *every["server"]] and len(every["client"]) == 7
    sections = re.split(r"^### ", page, flags=re.MULTILINE)[1:]
    for section, schema in zip(sections, [*every["client"].values(), *every["server"].values()], strict=True):
        assert _first_column(section) == [name for name in schema["properties"] if name != "type"]
    # the bounds the client's schema carries are the page's too
    takes = gen.cell("3 numbers (>= -1e9, <= 1e9) each")
    assert f"| `eye` | {takes} | required |" in gen.websocket_reference(every)


def _first_line(docstring: str | None) -> str:
    """A docstring's first line as the page shows it: code without its backticks, roles without their names."""
    assert docstring, "a public name without a docstring"
    return re.sub(r":[a-z]+:|`", "", docstring.strip().splitlines()[0])

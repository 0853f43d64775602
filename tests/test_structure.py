"""The package's structure, read from its import graph (``ast``: module-level and function-level imports alike):
no two modules import each other, directly or round a cycle; nobody imports another module's underscore names;
and the layers below the service (``util``, ``camera``, ``engine``, ``settings``, ``scene``, ``painting``,
``media``) never import the service, the benchmarks or the command line; no function outside the compiled kernels
runs over sixty lines and no class over two hundred; no test module imports another test module, conftests hold
fixtures only, and the tests reach servers through one door."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "rcp_server"
LOWER = ("util", "camera", "engine", "settings", "scene", "painting", "media")
ABOVE = ("rcp_server.service", "rcp_server.bench", "rcp_server.cli")


def _modules() -> dict[str, Path]:
    """Every module of the package: dotted name -> file (a package is its ``__init__``)."""
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


MODULES = _modules()


def _imports(name: str, path: Path) -> list[tuple[str, str | None, int]]:
    """What ``name`` imports, anywhere in its file: (module, imported name or None, line), relative imports
    resolved; a ``from package import submodule`` counts as importing the submodule."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(alias.name, None, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, *([base] if base else [])])
            for alias in node.names:
                if f"{base}.{alias.name}" in MODULES:
                    found.append((f"{base}.{alias.name}", None, node.lineno))
                else:
                    found.append((base, alias.name, node.lineno))
    return found


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _edges() -> dict[str, set[str]]:
    """Module -> the package's modules it imports (a package's ``__init__`` is a module like the others)."""
    return {
        name: {target for target, _, _ in imports if target in MODULES and target != name}
        for name, imports in GRAPH.items()
    }


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted: the import cycles."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return sorted(components)


def test_the_graph_sees_the_whole_package():
    assert {"rcp_server", "rcp_server.cli", "rcp_server.engine.kernels.embree", "rcp_server.service.app"} <= set(
        MODULES
    )
    assert "rcp_server.engine.kernels.embree" in _edges()["rcp_server.painting.seen"]  # relative imports resolved


def test_no_module_imports_another_that_imports_it_back():
    """A package's ``__init__`` counts as the module it is: ``painting.raytrace`` importing ``engine.kernels`` imports
    every kernel module that ``kernels/__init__.py`` imports."""
    assert _cycles(_edges()) == []


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_underscore_name_is_imported_from_another_module():
    private = [
        f"{MODULES[source].relative_to(PACKAGE.parent)}:{line}: {name} from {target}"
        for source, imports in GRAPH.items()
        for target, name, line in imports
        if target.startswith("rcp_server") and name is not None and name.startswith("_") and not name.startswith("__")
    ]
    assert private == []


def test_the_layers_below_the_service_never_import_it_the_benchmarks_or_the_command():
    upward = [
        f"{source} imports {target}"
        for source, imports in GRAPH.items()
        if source.split(".")[1:2] and source.split(".")[1] in LOWER
        for target, _, _ in imports
        if any(target == above or target.startswith(above + ".") for above in ABOVE)
    ]
    assert upward == []


LONGEST = 60  # lines a function may take, outside the compiled kernels (their loops are fused on purpose)
LARGEST = 200  # lines a class may take, outside the compiled kernels


def _outside_the_kernels(kind, limit: int) -> list[str]:
    """Every ``kind`` of node (functions, or classes) over ``limit`` lines outside the compiled kernels."""
    return [
        f"{path.relative_to(PACKAGE.parent)}:{node.lineno} {node.name} ({node.end_lineno - node.lineno + 1} lines)"
        for name, path in MODULES.items()
        if not name.startswith("rcp_server.engine.kernels")
        for node in ast.walk(ast.parse(path.read_text(), str(path)))
        if isinstance(node, kind) and node.end_lineno - node.lineno + 1 > limit
    ]


def test_no_function_outside_the_kernels_runs_over_sixty_lines():
    assert _outside_the_kernels(ast.FunctionDef | ast.AsyncFunctionDef, LONGEST) == []


def test_no_class_outside_the_kernels_runs_over_two_hundred_lines():
    assert _outside_the_kernels(ast.ClassDef, LARGEST) == []


TESTS = PACKAGE.parent / "tests"


def test_no_test_module_imports_another_test_module_or_a_conftest():
    """Tests share through ``tests/helpers/`` (what is not a fixture) and conftests (fixtures only)."""
    found = []
    for path in sorted(TESTS.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = []
            if isinstance(node, ast.ImportFrom):
                names = [node.module or ""] + [f"{node.module or ''}.{alias.name}" for alias in node.names]
            elif isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            bad = [n for n in names if any(part.startswith("test_") or part == "conftest" for part in n.split("."))]
            if bad:
                found.append(f"{path.relative_to(TESTS)}:{node.lineno} imports {bad[0]}")
    assert found == []


def _is_fixture(node: ast.FunctionDef) -> bool:
    return any(
        (isinstance(d, ast.Attribute) and d.attr == "fixture")
        or (isinstance(d, ast.Call) and isinstance(d.func, ast.Attribute) and d.func.attr == "fixture")
        for d in node.decorator_list
    )


def test_conftests_hold_fixtures_only():
    """What a conftest defines is a fixture or a pytest hook; any other helper lives in ``tests/helpers/``."""
    found = [
        f"{path.relative_to(TESTS)}:{node.lineno} {node.name}"
        for path in sorted(TESTS.rglob("conftest.py"))
        for node in ast.parse(path.read_text(), str(path)).body
        if isinstance(node, ast.ClassDef)
        or (isinstance(node, ast.FunctionDef) and not _is_fixture(node) and not node.name.startswith("pytest_"))
    ]
    assert found == []


# where the service picks its painter, here or on Ray, and the settings that declare the address it reads
SERVICE_PORT_CHOICE = ("rcp_server.service.state", "rcp_server.service.settings")
RAY_WORDS = {"cluster", "walks", "on_cluster", "ray_address", "RayPainter", "RayPort", "ClusterError"}


def test_nothing_in_the_service_but_the_painters_choice_asks_about_ray():
    """The walk, the routes and the films call the painter port; only the service's opening picks it."""
    found = []
    for name, path in MODULES.items():
        if not name.startswith("rcp_server.service") or name in SERVICE_PORT_CHOICE:
            continue
        for target, _, line in GRAPH[name]:
            if target.startswith("rcp_server.cluster"):
                found.append(f"{name}:{line} imports {target}")
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            word = node.attr if isinstance(node, ast.Attribute) else node.id if isinstance(node, ast.Name) else None
            if word in RAY_WORDS:
                found.append(f"{name}:{node.lineno} reads {word}")
    assert found == []


SERVERS = "rcp_server.service.loopback"  # the servers on loopback that the benchmarks and the tests share


def test_tests_reach_servers_only_through_the_helpers_door():
    """``tests/helpers/servers.py`` is the tests' one import of the servers on loopback: nothing else in ``tests/``
    imports that module, or the benchmarks' old home of it."""
    found = []
    for path in sorted(TESTS.rglob("*.py")):
        if path == TESTS / "helpers" / "servers.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = []
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module] + [f"{node.module}.{alias.name}" for alias in node.names]
            elif isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            if any(n in (SERVERS, "rcp_server.bench.harness") for n in names):
                found.append(f"{path.relative_to(TESTS)}:{node.lineno}")
    assert found == []

"""``rcp bench X``: each benchmark its own subcommand with its own flags; a missing package is one line naming the
extra, exit code 2; and the benchmarks import on a plain install (no test extra)."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from rcp_server.cli import main

ROOT = Path(__file__).resolve().parents[2]
FLAGS = {
    "speed": {"--scene", "--width", "--height", "--iterations", "--repeats", "--threads"},
    "latency": {"--scene", "--seconds", "--steps"},
    "soak": {"--seconds", "--clients", "--rest"},
    "accuracy": {"--out", "--quick", "--threads"},
    "stability": {"--out", "--quick", "--noise-only"},
    "cluster": {
        "--scene",
        "--width",
        "--height",
        "--frames",
        "--ray",
        "--gbps",
        "--cores",
        "--server-cores",
        "--walkers-only",
        "--overhead-ms",
    },
    "walkers": {"--ray", "--scene", "--width", "--height", "--seconds", "--crew"},
    "memory": {"--width", "--height", "--threads"},
    "flicker": {"--scene", "--width", "--height", "--fps", "--frames", "--temporal", "--boil"},
}
# what a plain install lacks: the test extra's packages (the bench extra's among them)
NOT_PLAIN = ("httpx", "matplotlib", "skimage", "playwright", "schemathesis", "pytest", "xdist")


def _python(code: str, tmp_path: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    return subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True)


def _blocked(modules) -> str:
    """Python that makes ``modules`` unimportable, as if they were not installed."""
    return f"import sys; sys.modules.update(dict.fromkeys({tuple(modules)!r}))\n"


@pytest.mark.parametrize("which", sorted(FLAGS))
def test_each_benchmark_has_its_own_help_and_flags(which, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["bench", which, "--help"])
    assert stop.value.code == 0
    shown = capsys.readouterr().out
    assert shown.startswith(f"usage: rcp bench {which} ")
    assert set(re.findall(r"(?<![\w-])--[a-z][a-z-]*", shown)) == FLAGS[which] | {"--help"}


def test_bench_lists_every_benchmark(capsys):
    with pytest.raises(SystemExit):
        main(["bench", "--help"])
    shown = capsys.readouterr().out
    assert all(re.search(rf"^\s+{name}\s", shown, re.MULTILINE) for name in FLAGS), shown


@pytest.mark.parametrize(
    "argv,message",
    [
        (["bench", "soak", "--repeats", "3"], "unrecognized arguments: --repeats 3"),  # speed's flag
        (["bench", "stability", "--threads", "2"], "unrecognized arguments: --threads 2"),
        (["bench", "fastest"], "argument BENCHMARK: invalid choice: 'fastest'"),
        (["bench"], "the following arguments are required: BENCHMARK"),
        (["bench", "latency", "--seconds", "inf"], "must be a finite number, got inf"),
    ],
)
def test_a_flag_of_another_benchmark_or_a_bad_value_is_one_line(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("rcp: error: ") and message in err and err.count("\n") == 1, err


@pytest.mark.parametrize(
    "which,module,requirement",
    [
        ("accuracy", "matplotlib", "matplotlib"),
        ("stability", "matplotlib", "matplotlib"),
        ("soak", "websockets", "websockets>=14"),
        ("latency", "websockets", "websockets>=14"),
    ],
)
def test_a_missing_package_is_one_line_naming_the_extra(which, module, requirement, tmp_path):
    argv = ["bench", which, "--seconds", "1"] if module == "websockets" else ["bench", which, "--quick"]
    code = _blocked([module]) + f"from rcp_server.cli import main\nsys.exit(main({argv!r}))\n"
    run = _python(code, tmp_path)
    assert run.returncode == 2, run.stderr
    assert run.stderr == (
        f"rcp: error: rcp bench {which} needs {requirement}, which the bench extra installs: "
        "pip install '.[bench]' in the rcp source folder\n"
    )
    assert run.stdout == "" and list(tmp_path.iterdir()) == []  # refused before measuring or writing anything


def test_the_benchmarks_import_without_the_test_extra(tmp_path):
    modules = [
        "cli",
        "speed",
        "latency",
        "soak",
        "metrics",
        "accuracy",
        "stability",
        "cluster",
        "memory",
        "walkers",
        "walkmodel",
        "flicker",
    ]
    code = _blocked(NOT_PLAIN) + "".join(f"import rcp_server.bench.{name}\n" for name in modules)
    code += "import rcp_server.service.loopback\n"  # the benchmarks' servers on loopback
    code += "assert not {'httpx', 'matplotlib'} & {m.split('.')[0] for m in sys.modules if sys.modules[m]}\n"
    run = _python(code, tmp_path)
    assert run.returncode == 0, run.stderr

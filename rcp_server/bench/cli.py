"""``rcp bench X``: one subcommand per benchmark, each with its own flags.

A benchmark's module is imported only when it runs, after the packages it needs beyond a plain install are
found: a missing one is reported in one line that names the extra to install (``MissingExtra``, exit code 2),
never as a traceback minutes into a run.
"""

from __future__ import annotations

import argparse
import importlib.util
from functools import partial
from pathlib import Path

from ..util.argtypes import finite, positive_int

EXTRA = "pip install '.[bench]' in the rcp source folder"
# (module to find, requirement to name): what the bench extra adds to a plain install
MATPLOTLIB = ("matplotlib", "matplotlib")
WEBSOCKETS = ("websockets.asyncio.client", "websockets>=14")  # a plain install has it through uvicorn[standard]
SCHEMATHESIS = ("schemathesis", "schemathesis>=4.32,<5")  # the test extra's: pip install -e ".[test]"


class MissingExtra(Exception):
    """A benchmark needs a package that this install lacks; the message says which extra brings it."""


def _findable(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a parent package missing, or blocked (None in sys.modules)
        return False


def require(benchmark: str, *needs: tuple[str, str]) -> None:
    """Raise ``MissingExtra`` unless every ``(module, requirement)`` of ``needs`` can be imported."""
    missing = [requirement for module, requirement in needs if not _findable(module)]
    if missing:
        raise MissingExtra(f"rcp bench {benchmark} needs {', '.join(missing)}, which the bench extra installs: {EXTRA}")


# ---- what each subcommand runs ----


def _speed(args: argparse.Namespace) -> None:
    from .speed import speed

    speed(args.scene, args.width, args.height, args.iterations, args.repeats, args.threads)


def _projection(args: argparse.Namespace) -> None:
    from .projection import bench_projection

    bench_projection(args.scene, args.width, args.repeats, args.ipd)


def _latency(args: argparse.Namespace) -> None:
    require("latency", WEBSOCKETS)
    from .latency import latency

    latency(args.scene, args.seconds, args.steps)


def _soak(args: argparse.Namespace) -> None:
    require("soak", WEBSOCKETS)
    from .soak import bench_soak

    bench_soak(args.seconds, args.clients, args.rest)


def _fuzz(args: argparse.Namespace) -> None:
    if not _findable(SCHEMATHESIS[0]):
        raise MissingExtra(
            f"rcp bench fuzz needs {SCHEMATHESIS[1]}, which the test extra installs: pip install -e '.[test]'"
        )
    from .fuzz import fuzz

    if fuzz(args.examples, args.seed):
        raise SystemExit(1)


def _accuracy(args: argparse.Namespace) -> None:
    require("accuracy", MATPLOTLIB)  # for the chart, drawn at the end: refuse before measuring for minutes
    from .accuracy import run

    run(args.out, quick=args.quick, threads=args.threads)


def _stability(args: argparse.Namespace) -> None:
    require("stability", MATPLOTLIB)
    from .stability import run

    run(args.out, quick=args.quick, noise_only=args.noise_only)


def _memory(args: argparse.Namespace) -> None:
    from ..painting.loop import default_threads
    from .memory import bench_memory

    bench_memory(args.models, args.width, args.height, args.threads or default_threads())


def _cluster(args: argparse.Namespace) -> None:
    if not _findable("ray"):
        raise MissingExtra("rcp bench cluster needs Ray, which the cluster extra installs: pip install '.[cluster]'")
    from .cluster import bench_cluster

    bench_cluster(
        args.scene,
        args.width,
        args.height,
        args.frames,
        args.ray,
        args.gbps,
        args.cores,
        args.walkers_only,
        args.server_cores,
        args.overhead_ms,
    )


def _walkers(args: argparse.Namespace) -> None:
    require("walkers", WEBSOCKETS)
    if args.ray and not _findable("ray"):
        raise MissingExtra(
            "rcp bench walkers --ray needs Ray, which the cluster extra installs: pip install '.[cluster]'"
        )
    from .walkers import bench_crew, bench_walkers

    if args.crew:
        if not _findable("ray"):
            raise MissingExtra("rcp bench walkers --crew needs Ray, which the cluster extra installs")
        bench_crew(args.crew, args.scene, args.width, args.height, args.seconds)
        return
    bench_walkers(args.walkers, args.ray, args.scene, args.width, args.height, args.seconds)


def _restart(args: argparse.Namespace) -> None:
    from .restart import bench_restart

    bench_restart(args.model, args.triangles, args.width, args.height)


# ---- the subcommands ----


def _out_and_quick(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--out", type=Path, default=Path("bench-out"), help="folder for the JSON and the PNG chart (default bench-out)"
    )
    p.add_argument("--quick", action="store_true", help="a smaller, faster run (320x180)")


def add_bench_commands(subparsers) -> None:
    """Add ``bench`` and its subcommands to ``rcp``'s subparsers; each sets ``run_bench(args)``."""
    bench = subparsers.add_parser(
        "bench",
        help="benchmarks that print figures (accuracy and stability also chart them)",
        description="Benchmarks that print figures; 'rcp bench BENCHMARK --help' gives each one's flags.",
    )
    command = partial(_command, bench.add_subparsers(dest="benchmark", required=True, metavar="BENCHMARK"))
    _engine_benchmarks(command)
    _film_benchmarks(command)
    _service_benchmarks(command)
    _cluster_benchmarks(command)


def _command(which, name: str, summary: str) -> argparse.ArgumentParser:
    return which.add_parser(name, help=summary, description=f"rcp bench {name}: {summary}.")


def _engine_benchmarks(command) -> None:
    """The engine's: its speed, projections, accuracy, stability and memory."""
    p = command("speed", "the engine against Embree alone: where an iteration's time goes")
    p.add_argument("--scene", default="default", help="a scene name, scene file or mesh file (default: default)")
    p.add_argument("--width", type=positive_int, default=640, help="pixels (default 640)")
    p.add_argument("--height", type=positive_int, default=360, help="pixels (default 360)")
    p.add_argument("--iterations", type=positive_int, default=6, help="recursion depth (default 6)")
    p.add_argument(
        "--repeats", type=positive_int, default=5, help="paintings timed, each paired with Embree alone (default 5)"
    )
    p.add_argument("--threads", type=positive_int, help="worker threads (default: all cores)")
    p.set_defaults(run_bench=_speed)

    p = command("projection", "a panorama and a stereo pair against a perspective painting: cost, and eyes in rivalry")
    p.add_argument("--scene", default="default", help="a scene name, scene file or mesh file (default: default)")
    p.add_argument(
        "--width", type=positive_int, default=640, help="an eye's image width; its height is half (default 640)"
    )
    p.add_argument("--repeats", type=positive_int, default=5, help="paintings timed of each kind (default 5)")
    p.add_argument("--ipd", type=finite, help="distance between the eyes, scene units (default: the scene camera's)")
    p.set_defaults(run_bench=_projection)

    p = command("accuracy", "time per frame against error, both methods (needs the bench extra)")
    _out_and_quick(p)
    p.add_argument("--threads", type=positive_int, help="worker threads (default: all cores)")
    p.set_defaults(run_bench=_accuracy)

    p = command("stability", "where each method breaks (needs the bench extra)")
    _out_and_quick(p)
    p.add_argument("--noise-only", action="store_true", help="only the walk flicker of the two kinds of noise")
    p.set_defaults(run_bench=_stability)

    p = command("memory", "resident memory per loaded scene, and its peak once painted, over the interpreter")
    p.add_argument(
        "models", nargs="*", metavar="MODEL", help="model files (or scene files) measured after the shipped scenes"
    )
    p.add_argument("--width", type=positive_int, default=1280, help="pixels (default 1280)")
    p.add_argument("--height", type=positive_int, default=720, help="pixels (default 720)")
    p.add_argument("--threads", type=positive_int, help="worker threads (default: all cores)")
    p.set_defaults(run_bench=_memory)


WALK = Path(__file__).resolve().parents[2] / "examples" / "walk.json"


def _flicker(args: argparse.Namespace) -> None:
    from .flicker import flicker

    flicker(args)


def _film_benchmarks(command) -> None:
    """The films': how much a painting flickers along a path."""
    p = command("flicker", "the warping error of a film along a path, plain and painted, per frame and temporal")
    p.add_argument("path", nargs="?", default=str(WALK), help="a camera path file (default: examples/walk.json)")
    p.add_argument("--scene", default="default", help="a scene name, scene file or mesh file (default: default)")
    p.add_argument("--width", type=positive_int, default=320, help="pixels (default 320)")
    p.add_argument("--height", type=positive_int, default=180, help="pixels (default 180)")
    p.add_argument("--fps", type=finite, default=8.0, help="frames a second along the path (default 8)")
    p.add_argument("--frames", type=positive_int, help="only the first this many frames")
    p.add_argument("--temporal", type=positive_int, default=1, help="iterations a frame of the temporal film (1)")
    p.add_argument("--boil", type=int, help="reseed the noise every this many frames (default: the scene's)")
    p.set_defaults(run_bench=_flicker)


def _service_benchmarks(command) -> None:
    """The service's: latency, load, fuzzing, restarts."""
    p = command("latency", "the walk-through's latency and frame rate, against a real server")
    p.add_argument("--scene", default="default", help="a scene the server serves (default: default)")
    p.add_argument("--seconds", type=finite, default=4.0, help="seconds of walking per size and mode (default 4)")
    p.add_argument("--steps", type=positive_int, default=10, help="single camera steps from rest (default 10)")
    p.set_defaults(run_bench=_latency)

    p = command("soak", "rcp serve under WebSocket and REST load: its memory and threads after")
    p.add_argument("--seconds", type=finite, default=60.0, help="seconds of load (default 60)")
    p.add_argument(
        "--clients",
        type=positive_int,
        default=6,
        help="WebSocket walk-throughs at once (the server takes RCP_MAX_SESSIONS, 8; default 6)",
    )
    p.add_argument(
        "--rest",
        type=int,
        default=2,
        choices=range(0, 65),
        metavar="0..64",
        help="REST callers posting renders back to back (default 2)",
    )
    p.set_defaults(run_bench=_soak)

    p = command("fuzz", "the REST API fuzzed from its OpenAPI schema with a random seed; prints what it finds")
    p.add_argument("--examples", type=positive_int, default=300, help="examples an operation (default 300)")
    p.add_argument("--seed", type=int, help="the seed of an earlier run, to repeat it (default: a random one)")
    p.set_defaults(run_bench=_fuzz)

    p = command("restart", "rcp serve killed and started again: how soon it serves a stored upload")
    p.add_argument("--model", type=Path, help="a model file to upload (default: a sphere built in code)")
    p.add_argument(
        "--triangles",
        type=positive_int,
        default=330_000,
        help="about as many triangles in the built sphere (default 330,000)",
    )
    p.add_argument("--width", type=positive_int, default=640, help="first frames' pixels (default 640)")
    p.add_argument("--height", type=positive_int, default=360, help="first frames' pixels (default 360)")
    p.set_defaults(run_bench=_restart)


def _cluster_benchmarks(command) -> None:
    """Ray's: walkers, films and the models of N machines."""
    p = command("walkers", "N walkers at once against rcp serve: each one's frame rate, size and latency, and CPU")
    p.add_argument("walkers", type=positive_int, help="walk-throughs at once")
    p.add_argument("--ray", metavar="ADDRESS", help="paint on Ray: 'local' (a runtime here) or a cluster's address")
    p.add_argument("--scene", default="default", help="a scene the server serves (default: default)")
    p.add_argument("--width", type=positive_int, default=640, help="each walker's pixels (default 640)")
    p.add_argument("--height", type=positive_int, default=360, help="each walker's pixels (default 360)")
    p.add_argument("--seconds", type=finite, default=10.0, help="seconds measured, after a warm-up (default 10)")
    p.add_argument(
        "--crew",
        type=positive_int,
        metavar="NODES",
        help="one walker's frames in bands on NODES nodes of Ray's test cluster (one CPU each), against threads",
    )
    p.set_defaults(run_bench=_walkers)

    p = command("cluster", "a camera path on Ray against this machine's threads, and a model of N machines")
    p.add_argument("--scene", default="default", help="a scene name, scene file or mesh file (default: default)")
    p.add_argument("--width", type=positive_int, default=320, help="pixels (default 320)")
    p.add_argument("--height", type=positive_int, default=180, help="pixels (default 180)")
    p.add_argument("--frames", type=positive_int, default=24, help="frames of the path (default 24)")
    p.add_argument("--ray", metavar="ADDRESS", help="a Ray cluster (default: a local Ray runtime on this machine)")
    p.add_argument("--gbps", type=finite, default=10.0, help="the model's network to the encoder, Gbit/s (default 10)")
    p.add_argument("--cores", type=positive_int, default=32, help="the model's cores per machine (default 32)")
    p.add_argument(
        "--server-cores", type=positive_int, default=4, help="the walkers' model: the server's cores (default 4)"
    )
    p.add_argument("--walkers-only", action="store_true", help="only the walkers' figures and model")
    p.add_argument(
        "--overhead-ms",
        type=finite,
        help="the crew's model: a frame's round trip beyond its painting, as rcp bench walkers measures it on a crew",
    )
    p.set_defaults(run_bench=_cluster)

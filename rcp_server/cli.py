"""``rcp``: paint stills and sequences, list scenes, benchmark. Bad arguments: one line, exit code 2."""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import signal
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

from .bench.cli import MissingExtra, add_bench_commands
from .camera.camera import CAMERA_FIELDS, Camera, CameraError
from .cluster.painter import ClusterError
from .engine.kernels.embree import EmbreeMissing
from .media import prints, video
from .media.camerapath import CAMERA_PREFIX, PathError, PathFrame, load_path, motion_path
from .media.prints import BAND_PIXELS, BITS, MAX_SIDE
from .painting.loop import PaintState, paint
from .painting.sequence import paint_sequence
from .scene.scene import Scene
from .scene.scenefile import SceneError, load_environment, load_scene, scene_names
from .service.store import DataFolderError
from .settings.params import PAINT_SETTINGS, PER, PaintParams
from .settings.styles import STYLE, STYLES
from .util import images
from .util.argtypes import finite, positive_int

log = logging.getLogger("rcp")


class UsageError(Exception):
    """A command line that cannot run; reported in one line with exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse prints usage and a message over two lines; we want one
        raise UsageError(message)


def _add_paint_options(p: argparse.ArgumentParser) -> None:
    """One option per painting setting (``--lambda-p`` for ``lambda_p``), from its declaration; the bounds
    are checked once, by :class:`PaintParams`."""
    g = p.add_argument_group("painting (defaults: the scene's [paint] table, then the engine's)")
    g.add_argument(
        "--paint",
        type=Path,
        metavar="FILE",
        help="painting settings from a JSON or TOML file, settings per object and per material among them "
        '(\'{"objects": {"figure": {"lambda_p": 0}}}\'); the options below replace its own',
    )
    g.add_argument(
        "--style",
        choices=tuple(STYLES),
        help="a named look (its settings replace the scene's; the options below replace the style's)",
    )
    for name, declared in PAINT_SETTINGS.items():
        open_names = declared.lookup is not None  # more can be registered: the engine says which it knows
        help = declared.help + (f": {', '.join(declared.choices)}" if open_names else "")
        help += "" if declared.default is None else f" (default {declared.default})"
        flag = f"--{name.replace('_', '-')}"
        if declared.kind is bool:  # --hatch / --no-hatch
            g.add_argument(flag, action=argparse.BooleanOptionalAction, default=None, help=help)
            continue
        choices = None if open_names or not declared.choices else declared.choices
        g.add_argument(flag, type=declared.kind, choices=choices, help=help)


def _add_camera_options(p: argparse.ArgumentParser) -> None:
    """One option per camera field (``camera.CAMERA_FIELDS``); left out, the scene camera's."""
    g = p.add_argument_group("camera (default: the scene's)")
    for name, declared in CAMERA_FIELDS.items():
        flag = "--" + name.replace("_", "-")
        if declared.kind == "vec3":
            g.add_argument(flag, nargs=3, type=finite, metavar=("X", "Y", "Z"), help=declared.help)
        elif declared.kind is str:
            g.add_argument(flag, choices=declared.choices, help=declared.help)
        else:
            g.add_argument(flag, type=finite, help=declared.help)


def _parser() -> argparse.ArgumentParser:
    """``rcp``'s parser: the global flags and one subcommand each for render, scenes, compile, serve and bench."""
    parser = _Parser(prog="rcp", description="Recursive Camera Painting: paint 3D scenes with per-pixel cameras.")
    parser.add_argument("-q", "--quiet", action="store_true", help="no warnings or progress")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    _add_render_command(sub)
    sub.add_parser("scenes", help="list the shipped scenes")
    sub.add_parser(
        "compile",
        help="compile the kernels into numba's cache (NUMBA_CACHE_DIR) as `rcp serve` does as it starts, so that "
        "the next start is ready at once (a container image does it when it is built)",
    )
    v = sub.add_parser("serve", help="serve the walk-through client, REST renders and the WebSocket")
    v.add_argument("--host", help="address to listen on (default 127.0.0.1, or RCP_HOST)")
    v.add_argument("--port", type=int, help="port (default 8000, or RCP_PORT)")
    add_bench_commands(sub)
    return parser


def _add_render_command(sub) -> None:
    """``rcp render``: the scene, output, size, painting and camera options, then those of a sequence."""
    r = sub.add_parser("render", help="paint a still, its iterations, or a sequence")
    r.add_argument("scene", help="a scene name (see 'rcp scenes'), a scene .toml file, or a mesh file")
    r.add_argument(
        "--out",
        required=True,
        type=Path,
        help="image file (.png, .jpg); for a sequence (--path, --frames): an .mp4 video (H.264), a folder of "
        "numbered PNGs (frames/), or an image name whose stem gets _0000, _0001, ...",
    )
    r.add_argument("--width", type=positive_int, default=640)
    r.add_argument("--height", type=positive_int, default=360)
    _add_paint_options(r)
    _add_camera_options(r)
    r.add_argument("--time", type=finite, default=0.0, help="scene time in seconds (animated scenes)")
    r.add_argument(
        "--environment",
        type=Path,
        metavar="IMAGE",
        help="replace what misses see: an equirectangular image or Radiance .hdr panorama",
    )
    r.add_argument("--exposure", type=finite, default=0.0, help="stops of exposure for a .hdr environment")
    r.add_argument("--save-iterations", type=Path, metavar="DIR", help="also write every iteration to DIR")
    r.add_argument("--threads", type=positive_int, help="worker threads (default: all cores; on Ray: per worker, 1)")
    r.add_argument(
        "--ray",
        nargs="?",
        const="local",
        metavar="ADDRESS",
        help="paint on Ray (the cluster extra): a local Ray runtime, or the cluster at ADDRESS (or RAY_ADDRESS)",
    )
    r.add_argument("--quality", type=int, default=92, choices=range(1, 101), metavar="1..100", help="JPEG quality")
    r.add_argument(
        "--alpha", action="store_true", help="a PNG with alpha 0 where the plain image sees no geometry (a still)"
    )
    r.add_argument("--bits", type=int, choices=BITS, default=8, help="bits a channel of a PNG still (default 8)")
    _add_sequence_options(r)


def _add_sequence_options(r: argparse.ArgumentParser) -> None:
    """``rcp render``'s sequence options: frames, a camera path, fps, an orbit, a walk and temporal mode."""
    s = r.add_argument_group("sequences")
    s.add_argument("--frames", type=positive_int, default=1, help="number of frames")
    s.add_argument(
        "--path",
        metavar="JSON",
        help="a camera path (keyframes; the client saves them): one frame every 1/fps along it; or camera:NAME, "
        "an animated camera of the model (a glTF's)",
    )
    s.add_argument("--fps", type=finite, help="frames per second of scene time (default 24, or the path's)")
    s.add_argument(
        "--orbit",
        type=finite,
        default=0.0,
        metavar="DEG",
        help="turn the eye this many degrees around look-at over the sequence",
    )
    s.add_argument(
        "--walk",
        type=finite,
        default=0.0,
        metavar="DIST",
        help="move eye and look-at this far forward over the sequence",
    )
    s.add_argument(
        "--temporal",
        type=positive_int,
        metavar="K",
        help="temporal mode: after the first frame, run K iterations from the previous frame",
    )


def paint_file(path: Path) -> dict:
    """Painting settings by name from a JSON or TOML file (by its suffix); one line naming it if it is not one."""
    try:
        text = path.read_text(encoding="utf-8")
        values = tomllib.loads(text) if path.suffix.lower() == ".toml" else json.loads(text)
    except OSError as exc:
        raise UsageError(f"--paint {path}: cannot read ({exc.strerror})") from None
    except (ValueError, UnicodeDecodeError) as exc:  # JSON's and TOML's errors are ValueErrors
        raise UsageError(
            f"--paint {path}: not valid {'TOML' if path.suffix.lower() == '.toml' else 'JSON'} ({exc})"
        ) from None
    if not isinstance(values, dict):
        raise UsageError(f"--paint {path}: give a table of painting settings, got {type(values).__name__}")
    unknown = set(values) - {STYLE, *PAINT_SETTINGS, *PER}
    if unknown:
        raise UsageError(f"--paint {path}: unknown settings {sorted(unknown)}; known: {sorted(PAINT_SETTINGS)}")
    return values


def paint_params(scene: Scene, args: argparse.Namespace) -> PaintParams:
    """The scene's painting settings, with the settings of ``--paint``, then the style and whatever else the
    command line gives in their place."""
    source = getattr(args, "paint", None)
    given = paint_file(source) if source is not None else {}
    given |= {name: value for name in (STYLE, *PAINT_SETTINGS) if (value := getattr(args, name, None)) is not None}
    try:
        return scene.painting(given)
    except ValueError as exc:
        raise UsageError(f"--paint {source}: {exc}" if source is not None else str(exc)) from None


def _camera(default: Camera, args: argparse.Namespace) -> Camera:
    changes = {
        name: tuple(v) if isinstance(v, list) else v
        for name in CAMERA_FIELDS
        if (v := getattr(args, name, None)) is not None
    }
    return default.moved(**changes)


def camera_path(camera: Camera, fraction: float, orbit_degrees: float, walk: float) -> Camera:
    """The camera a fraction of the way along an orbit around look-at and a walk forward."""
    eye, target = np.asarray(camera.eye), np.asarray(camera.look_at)
    if orbit_degrees:
        axis = np.asarray(camera.up) / np.linalg.norm(camera.up)
        angle = math.radians(orbit_degrees * fraction)
        v = eye - target  # Rodrigues' rotation of the eye about the up axis through the target
        v = v * math.cos(angle) + np.cross(axis, v) * math.sin(angle) + axis * axis.dot(v) * (1 - math.cos(angle))
        eye = target + v
    if walk:
        _, _, f = camera.moved(eye=tuple(eye)).basis()
        eye, target = eye + walk * fraction * f, target + walk * fraction * f
    return camera.moved(eye=tuple(eye), look_at=tuple(target))


def _frame_path(out: Path, index: int) -> Path:
    return out.with_name(f"{out.stem}_{index:04d}{out.suffix}")


def _render(args: argparse.Namespace) -> None:
    sequence = args.path is not None or args.frames > 1
    if args.path is not None and (args.frames > 1 or args.orbit or args.walk):
        raise UsageError("--path gives the frames and the cameras: leave out --frames, --orbit and --walk")
    if args.fps is not None and args.fps <= 0:
        raise UsageError(f"--fps must be positive, got {args.fps:g}")
    if not sequence or not (video.is_video(args.out) or video.is_folder(args.out)):
        images.image_format(args.out)  # refuse an unknown image type before painting anything
    scene = load_scene(args.scene)
    if args.environment is not None:
        scene.environment = load_environment(args.environment, args.exposure)
    params = paint_params(scene, args)
    base = _camera(scene.camera, args)
    # --width and --height are one eye's image; from here on they are the painting's (both eyes)
    args.width, args.height = base.image_size(args.width, args.height)
    if sequence and video.is_video(args.out):
        video.check_video_size(args.width, args.height)
    if sequence or args.ray is not None:
        if args.alpha or args.bits != 8:
            raise UsageError("--alpha and --bits make a still: leave out --path, --frames and --ray")
        _render_sequence(args, scene, params, base)
        return
    if (
        args.alpha
        or args.bits != 8
        or args.width * args.height > BAND_PIXELS
        or max(args.width, args.height) > MAX_SIDE
    ):
        _render_print(args, scene, params, base)
        return
    result = paint(
        scene,
        base,
        args.width,
        args.height,
        params,
        time=args.time,
        threads=args.threads,
        keep_iterations=args.save_iterations is not None,
    )
    images.save(args.out, result.image, args.quality)
    if args.save_iterations is not None:
        for k, image in enumerate(result.iterations, start=1):
            images.save(args.save_iterations / f"iteration_{k}.png", image)


def _render_print(args: argparse.Namespace, scene: Scene, params: PaintParams, camera: Camera) -> None:
    """A still in bands of rows, streamed to a PNG (``media/prints.py``): any size up to 16384 a side, memory
    bounded, with alpha and 16 bits when asked; a progress bar counts the rows."""
    from tqdm import tqdm

    prints.check_print(args.width, args.height, params, args.bits)  # before the progress bar shows
    if images.image_format(args.out) != "PNG":
        raise UsageError(f"--out {args.out}: a still this large, with --alpha or --bits 16, is written as a .png")
    if args.save_iterations is not None:
        raise UsageError("--save-iterations keeps whole iterations: a still this large paints in bands")

    def paint_band(band, band_params: PaintParams):
        return paint(scene, camera, args.width, args.height, band_params, time=args.time, region=band,
                     threads=args.threads)  # fmt: skip

    rows = prints.print_bands(scene, camera, args.width, args.height, params, paint_band, time=args.time,
                              bits=args.bits, alpha=args.alpha)  # fmt: skip
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with tqdm(total=args.height, desc="painting", unit="row", disable=args.quiet) as bar:
        prints.write_print(args.out, rows, args.width, args.height, args.bits, args.alpha, bar.update)


def _render_sequence(args: argparse.Namespace, scene, params: PaintParams, base: Camera) -> None:
    """Paint a camera path or an orbit and walk, into a video, a folder of PNGs or numbered images."""
    if args.save_iterations is not None and args.ray is not None:
        raise UsageError("--save-iterations paints here: leave out --ray")
    path, fps, count, shots = _sequence_shots(args, scene, params, base)
    writer = _sequence_writer(args, path, base, fps, count)
    _write_paintings(args, scene, params, shots, count, writer)


def _sequence_shots(args: argparse.Namespace, scene, params: PaintParams, base: Camera):
    """The sequence's camera path (None for an orbit and walk), its frames per second, its frame count and its
    shots (:class:`PathFrame`, lazily), from ``--path`` or from ``--frames``, ``--orbit`` and ``--walk``."""
    if args.path is None:
        fps, count = args.fps or 24.0, args.frames
        shots = (
            PathFrame(k, k / fps, camera_path(base, k / max(count - 1, 1), args.orbit, args.walk), args.time + k / fps)
            for k in range(count)
        )
        return None, fps, count, shots
    if args.path.startswith(CAMERA_PREFIX):
        distance = float(np.linalg.norm(np.subtract(base.look_at, base.eye)))
        path = motion_path(args.path, scene.motions, args.fps, distance)
    else:
        path = load_path(args.path, base, args.fps).with_painting(params, scene.check_names)
    shots = (frame._replace(scene_time=frame.scene_time + args.time) for frame in path.frames())
    return path, path.fps, path.frame_count, shots


def _sequence_writer(args: argparse.Namespace, path, base: Camera, fps: float, count: int) -> video.FrameWriter:
    """Where the sequence's frames go: one image (a still painted on Ray), a video or a folder of PNGs in the
    first camera's projection, or numbered images beside ``--out``."""
    if count == 1 and args.path is None:  # a still, painted on Ray
        return video.ImageFrames(lambda index: args.out, args.quality)
    if video.is_video(args.out) or video.is_folder(args.out):
        first = path.cameras[0] if path is not None else base  # a sequence keeps one projection
        return video.open_writer(args.out, args.width, args.height, fps, count, first.projection, first.stereo)
    return video.ImageFrames(lambda index: _frame_path(args.out, index), args.quality)


def _write_paintings(
    args: argparse.Namespace, scene, params: PaintParams, shots, count: int, writer: video.FrameWriter
) -> None:
    """Paint the shots here on threads or on Ray (``--ray``) and hand each image to ``writer`` under a progress
    bar; the writer is aborted if anything fails (or is interrupted), closed otherwise."""
    from tqdm import tqdm  # type: ignore[import-untyped]

    def paint_frame(camera: Camera, scene_time: float, frame_params: PaintParams, previous: PaintState | None):
        return paint(
            scene,
            camera,
            args.width,
            args.height,
            frame_params,
            time=scene_time,
            previous=previous,
            threads=args.threads,
        )

    painter = None
    try:
        if args.ray is None:
            paintings = paint_sequence(paint_frame, shots, params, args.temporal)
        else:
            from .cluster.painter import RayPainter

            painter = RayPainter(None if args.ray == "local" else args.ray, threads=args.threads or 1)
            painter.start()
            paintings = painter.images(scene, shots, args.width, args.height, params, args.temporal)
        with tqdm(total=count, desc="painting", unit="frame", disable=args.quiet) as bar:
            for image in paintings:
                writer.write(image)
                bar.update()
    except BaseException:
        writer.abort()
        raise
    finally:
        if painter is not None:
            painter.close()
    writer.close()


def _scenes() -> None:
    for name in scene_names():
        try:
            scene = load_scene(name)
            faces = scene.geometry(0.0)[0].face_count
            kind = "animated" if scene.animated else "static"
            print(f"{name:12s} {scene.title}  ({faces} triangles, {kind})")
        except SceneError as exc:
            print(f"{name:12s} BROKEN: {exc}")


def _settings(**given):
    """The server's settings: the ``RCP_*`` environment, with ``given`` command-line options over it; a misspelt
    variable or a bad value is a one-line usage error naming it."""
    from pydantic import ValidationError

    from .service.settings import Settings, setting_error, unknown_variable

    if unknown := unknown_variable(dict(os.environ)):
        raise UsageError(unknown)
    try:
        return Settings(**given)
    except ValidationError as exc:
        raise UsageError(setting_error(exc, {name: f"--{name}" for name in given})) from None


def _compile() -> None:
    from .painting import warmup
    from .service.state import load_scenes

    folder = _settings().scenes  # the scenes `rcp serve` serves (RCP_SCENES): each compiles what it calls
    clock = time.monotonic()
    scenes = load_scenes(folder)
    warmup.warm(scenes.values())
    print(f"rcp: the kernels of {len(scenes)} scenes are compiled (in {time.monotonic() - clock:.1f} s)")


def _serve(args: argparse.Namespace) -> None:
    from .service.server import Server

    settings = _settings(**{k: v for k, v in (("host", args.host), ("port", args.port)) if v is not None})
    logging.getLogger("rcp").setLevel(logging.INFO)
    for handler in logging.getLogger().handlers:
        handler.setFormatter(logging.Formatter("rcp: %(levelname)s: %(message)s"))
    # uvicorn stops gracefully on SIGINT or SIGTERM, then raises the signal again for the handler it found:
    # a stop asked for and carried out is exit status 0
    signal.signal(signal.SIGTERM, _stopped)
    signal.signal(signal.SIGINT, _stopped)

    def listening() -> None:  # said once the port answers, not before: the kernels may still compile meanwhile
        print(f"rcp: serving on http://{settings.host}:{settings.port}/  (walk-through client; API docs at /docs)")
        if settings.token is not None:
            print("rcp: a token is required (RCP_TOKEN): open the client at /#token=<token>")

    server = Server(settings, listening, log_level="info")
    try:
        sock = server.bind()
    except OSError as exc:
        where = f"{settings.host}:{settings.port}"
        raise UsageError(f"{where}: {exc.strerror or exc} (--port or RCP_PORT chooses another port)") from None
    server.open_service()  # the data folder and Ray: either failing is one line, before anyone is answered
    server.run(sockets=[sock])


def _stopped(signum, frame) -> None:
    raise SystemExit(0)


def main(argv: list[str] | None = None) -> int:
    logging.basicConfig(format="rcp: warning: %(message)s", level=logging.WARNING)
    try:
        args = _parser().parse_args(argv)
        if args.quiet:
            logging.getLogger("rcp").setLevel(logging.ERROR)
        if args.command == "render":
            _render(args)
        elif args.command == "scenes":
            _scenes()
        elif args.command == "compile":
            _compile()
        elif args.command == "serve":
            _serve(args)
        elif args.command == "bench":
            args.run_bench(args)
    except (
        UsageError,
        MissingExtra,
        SceneError,
        CameraError,
        PathError,
        ClusterError,
        DataFolderError,
        ValueError,
    ) as exc:
        print(f"rcp: error: {exc}", file=sys.stderr)
        return 2
    except EmbreeMissing as exc:  # the machine, not the arguments: one line, and the usual failure status
        print(f"rcp: error: {exc}", file=sys.stderr)
        return 1
    except MemoryError:
        print("rcp: error: not enough memory for this image size and sample count", file=sys.stderr)
        return 2
    except OSError as exc:  # an output path that cannot be written
        print(f"rcp: error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``rcp bench memory``: what a loaded scene costs in resident memory, and what painting it adds at its peak.

Each scene is measured in a fresh process of its own: the interpreter imports the engine (the baseline, its
resident size printed once), then loads the scene and builds its tree ("loaded": resident memory over the
baseline), then paints it once ("painted": the peak resident memory over the baseline, loading included).
Peaks are the kernel's high-water mark (``VmHWM``), reset after the imports (``/proc/self/clear_refs``).
This is what ``/usr/bin/time -v`` shows for ``rcp render`` less what it shows for an interpreter that only
imports rcp, and what the upload budget counts (``service/uploads.weight_of`` is its arrays' part).
"""

from __future__ import annotations

import json
import subprocess
import sys

from ..scene.scenefile import scene_names

CHILD = r"""
import json, sys, time
def status():
    out = {}
    for line in open("/proc/self/status"):
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            out[key] = int(value.split()[0]) * 1024
    return out
from rcp_server.painting import loop as painting
from rcp_server.painting.workspace import pixel_bytes
from rcp_server.scene import scenefile
from rcp_server.settings.params import PaintParams
ref, width, height, threads = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
base = status()
try:
    with open("/proc/self/clear_refs", "w") as reset:
        reset.write("5")  # the high-water mark starts again from here
    resettable = True
except OSError:
    resettable = False
start = time.perf_counter()
scene = scenefile.load_scene(ref)
geometry, _ = scene.geometry(0.0)
loaded_s = time.perf_counter() - start
loaded = status()
painting.paint(scene, scene.camera, width, height, scene.paint, threads=threads)
declared = pixel_bytes(scene.paint, outlines=bool((geometry.material_outline > 0).any()))
first_frame_s = time.perf_counter() - start
painted = status()
textures = geometry.texels.nbytes if geometry.texture_id.max(initial=-1) >= 0 else 0  # not the stand-in
print(json.dumps(dict(base=base["VmRSS"], loaded=loaded["VmRSS"] - base["VmRSS"],
    peak=painted["VmHWM"] - base["VmRSS"] if resettable else None, triangles=geometry.face_count,
    textures=textures, loaded_s=loaded_s, first_frame_s=first_frame_s, declared=declared)))
"""

MB = 1 << 20


def measure(ref: str, width: int, height: int, threads: int) -> dict:
    """One scene (a name, a scene file or a model file) measured in a fresh process: a dict of bytes and seconds."""
    run = subprocess.run(
        [sys.executable, "-c", CHILD, ref, str(width), str(height), str(threads)],
        capture_output=True,
        text=True,
        check=False,
    )
    if run.returncode != 0:
        last = (run.stderr.strip().splitlines() or ["it stopped"])[-1]
        raise RuntimeError(f"{ref}: {last}")
    return json.loads(run.stdout.strip().splitlines()[-1])


def bare_interpreter() -> int:
    """The resident size of an interpreter that has imported nothing of ours, bytes."""
    code = "for l in open('/proc/self/status'):\n if l.startswith('VmRSS'): print(int(l.split()[1]) * 1024)"
    return int(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)


def bench_memory(models: list[str], width: int, height: int, threads: int) -> None:
    """Print one line per scene: the shipped scenes, then each model file given."""
    refs = [*scene_names(), *models]
    print(f"rcp bench memory: each scene in a fresh process, painted once at {width}x{height} on {threads} threads")
    print(f"bare interpreter: {bare_interpreter() / MB:.0f} MB resident")
    base_shown = False
    print(
        f"bytes a pixel: the slope of the painted peak between {width}x{height} and {2 * width}x{2 * height}, "
        "beside what painting/workspace.py declares (the result, ink, anchor, picture)"
    )
    for ref in refs:
        try:
            m = measure(ref, width, height, threads)
            twice = measure(ref, 2 * width, 2 * height, threads)
        except RuntimeError as exc:
            print(f"{ref}: not measured ({exc})")
            continue
        if not base_shown:
            print(f"interpreter with rcp imported (the baseline below): {m['base'] / MB:.0f} MB resident")
            base_shown = True
        peak = "n/a" if m["peak"] is None else f"{m['peak'] / MB:.0f} MB"
        print(
            f"{ref}: {m['triangles']:,} triangles, textures {m['textures'] / MB:.0f} MB; "
            f"loaded +{m['loaded'] / MB:.0f} MB in {m['loaded_s']:.1f} s; "
            f"painted peak +{peak} (first frame {m['first_frame_s']:.1f} s after loading began)"
        )
        declared = m["declared"]
        parts = ", ".join(f"{name} {size}" for name, size in declared.items() if size)
        if m["peak"] is not None and twice["peak"] is not None:
            slope = (twice["peak"] - m["peak"]) / (3 * width * height)
            print(f"  {slope:.0f} bytes a pixel measured; {sum(declared.values())} declared ({parts})")

"""One traced iteration of one tile: every pixel's cameras, their hits (the screen cells of a fixed eye where
they prove the answer, Embree's packets elsewhere) and their shading, a compiled kernel each, called from
Python in turn (``raytrace.TracedTile`` calls this once an iteration). Each step is a kernel of its own
module, tested there against its numpy reference; this only chains and times them.

Chained here rather than in one compiled function: numba compiles every kernel a compiled function could call,
so a fused chain compiled the cut-out and extra-channel kernels of paintings that need neither, and itself
(about 5 s of a cold start's 15, ``painting/warmup.py``). Here a kernel compiles at its first call, the
slowest (``shade``) in another process meanwhile (``jit.compile_beside``), and the calls cost a few tens
of microseconds an iteration of a tile.
"""

from __future__ import annotations

from ...util.stopwatch import Stopwatch
from .alpha import pass_masked
from .cast import cast_rays
from .jit import compile_beside
from .shade import record_surfaces, shade
from .triangle import place_hits
from .visibility import find_faces


def paint_iteration(cast, source, out, trace, shading, scratch, watch: Stopwatch) -> int:
    """``I_n`` of a tile into ``out``, every pixel; returns how many pixels it painted.

    cast : bundles.Cast, the tile's cameras (its ``pixels`` field is ignored: every pixel is painted)
    source : bundles.Channels the displacement fields read: ``I_{n-1}``, or what the eyes of a stereo painting
    share (``stereo.py``);  out : bundles.Channels of the tile, never ``source``'s buffers
    trace : bundles.Trace, the scene's Embree handle and triangles (scene 0: no triangles, every ray misses)
    shading : bundles.Shading;  scratch : bundles.Scratch of the tile
    watch : the stopwatch the stages' seconds are added to (camera, intersect, shade)
    """
    n = out.color.shape[0]
    spp = cast.xi.shape[1]
    pixels = scratch.every[:n]
    traced = scratch.every[: n * spp]
    hits = scratch.hits
    shading_arguments = dict(
        origins=scratch.origins,
        directions=scratch.directions,
        hits=hits,
        spp=spp,
        pixels=pixels,
        surfaces=shading.surfaces,
        environment=shading.environment,
        light_dir=shading.light_dir,
        ambient=shading.ambient,
        lit=shading.lit,
        eye=cast.eye,
        plane=cast.plane,
        out=out,
        materials=shading.materials,
    )
    beside = compile_beside(shade, shading_arguments)  # the slowest to compile: on a cold cache, on another core
    with watch.stage("camera"):
        cast_rays(
            eye=cast.eye,
            plane=cast.plane,
            xi=cast.xi,
            eta=cast.eta,
            previous=source,
            z0=cast.z0,
            target=cast.target,
            eye_field=cast.eye_field,
            noise=cast.noise,
            noise_scale=cast.noise_scale,
            pixels=pixels,
            v_p=scratch.v_p,
            v_e=scratch.v_e,
            origins=scratch.origins,
            directions=scratch.directions,
            write_origins=cast.write_origins,
        )
    with watch.stage("intersect"):
        if trace.embree.scene == 0:
            hits.face[traced] = -1
        else:
            find_faces(
                screen=trace.screen,
                embree=trace.embree,
                origins=scratch.origins,
                directions=scratch.directions,
                rays=scratch.packets,
                face=hits.face,
                queue=scratch.queue,
            )
            place_hits(
                origins=scratch.origins,
                directions=scratch.directions,
                rays=traced,
                triangles=trace.triangles,
                hits=hits,
            )
            if trace.masked:  # ---- cut-outs let rays through ----
                pass_masked(
                    embree=trace.embree,
                    triangles=trace.triangles,
                    surfaces=shading.surfaces,
                    origins=scratch.origins,
                    directions=scratch.directions,
                    rays=traced,
                    hits=hits,
                    floor=trace.floor,
                    starts=scratch.starts,
                    todo=scratch.todo,
                    next_todo=scratch.next_todo,
                )
    with watch.stage("shade"):
        if beside is not None:
            beside.wait()
        shade(**shading_arguments)
        if any(shading.records):
            record_surfaces(
                origins=scratch.origins,
                directions=scratch.directions,
                hits=hits,
                spp=spp,
                pixels=pixels,
                surfaces=shading.surfaces,
                eye=cast.eye,
                plane=cast.plane,
                z_max=shading.z_max,
                out=out,
                need=shading.records,
            )
    return n

"""One traced iteration of one tile in one compiled call: every pixel's cameras, their hits (the screen
cells of a fixed eye where they prove the answer, Embree's packets elsewhere) and their shading, without
returning to Python in between (``raytrace.TracedTile`` calls it once an iteration). Each step is a kernel
of its own module, tested there against its numpy reference; this one only chains them and times them.
"""

from __future__ import annotations

from .alpha import pass_masked
from .cast import cast_rays
from .clock import cycles
from .jit import jit
from .shade import record_surfaces, shade
from .triangle import place_hits
from .visibility import find_faces


@jit
def paint_iteration(cast, source, out, trace, shading, scratch, clock):
    """``I_n`` of a tile into ``out``, every pixel; returns how many pixels it painted.

    cast : bundles.Cast, the tile's cameras (its ``pixels`` field is ignored: every pixel is painted)
    source : bundles.Channels the displacement fields read: ``I_{n-1}``, or what the eyes of a stereo painting
    share (``stereo.py``);  out : bundles.Channels of the tile, never ``source``'s buffers
    trace : bundles.Trace, the scene's Embree handle and triangles (scene 0: no triangles, every ray misses)
    shading : bundles.Shading;  scratch : bundles.Scratch of the tile
    clock : (3,) int64, cycles added per stage: camera, intersect, shade
    """
    start = cycles()
    n = out.color.shape[0]
    spp = cast.xi.shape[1]
    count = n
    pixels = scratch.every[:n]
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
    cast_end = cycles()
    rays = count * spp
    hits = scratch.hits
    traced = scratch.every[:rays]
    if trace.embree.scene == 0:
        for s in traced:
            hits.face[s] = -1
    else:
        find_faces(
            screen=trace.screen,
            embree=trace.embree,
            origins=scratch.origins,
            directions=scratch.directions,
            rays=traced,
            face=hits.face,
            queue=scratch.queue,
        )
        place_hits(
            origins=scratch.origins, directions=scratch.directions, rays=traced, triangles=trace.triangles, hits=hits
        )
        if trace.masked:  # ---- cut-outs let rays through ----
            pass_masked(
                embree=trace.embree,
                triangles=trace.triangles,
                surfaces=shading.surfaces,
                origins=scratch.origins,
                directions=scratch.directions,
                rays=scratch.every[:rays],
                hits=hits,
                floor=trace.floor,
                starts=scratch.starts,
                todo=scratch.todo,
                next_todo=scratch.next_todo,
            )
    intersect_end = cycles()
    shade(
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
        z_max=shading.z_max,
        out=out,
        need=shading.records,
        ink=shading.ink,
    )
    rec = shading.records
    if rec.geometric or rec.object or rec.material or rec.albedo or rec.uv or rec.position:
        record_surfaces(
            origins=scratch.origins,
            directions=scratch.directions,
            hits=hits,
            spp=spp,
            pixels=pixels,
            surfaces=shading.surfaces,
            out=out,
            need=rec,
        )
    clock[0] += cast_end - start
    clock[1] += intersect_end - cast_end
    clock[2] += cycles() - intersect_end
    return count

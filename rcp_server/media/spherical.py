"""Spherical-video metadata in an MP4: what makes 360° players and headsets show an equirect painting all
around the viewer, with no flag to set by hand.

Two generations of Google's open scheme are written, as its RFCs allow (a reader that knows both takes V2):

- **V2** (``docs/spherical-video-v2-rfc.md`` of google/spatial-media): an ``st3d`` box (stereo layout: 0 mono,
  1 top-bottom with the left eye on top, 2 left-right with the left eye left) and an ``sv3d`` box
  (``svhd`` naming the tool, ``proj`` holding ``prhd`` (pose 0, 0, 0) and ``equi`` (no crop)), in that order,
  inside the video track's sample entry (``avc1``), right after its codec configuration (``avcC``).
- **V1** (``docs/spherical-video-rfc.md``): the XML that Google's Spatial Media Metadata Injector writes, in
  a ``uuid`` box (``ffcc8263-f855-4a93-8814-587a02521fdd``) at the end of the video ``trak``.

FFmpeg's MP4 muxer writes V2 only from stream side data, which PyAV cannot set (it sets a display matrix and
nothing else), so the boxes are added to the finished file here: the boxes that contain them grow by as much,
and when the index (``moov``) comes before the media (``mdat``, an MP4 written with ``faststart``) every chunk
offset of ``stco``/``co64`` moves by the bytes inserted before the media.
"""

from __future__ import annotations

import os
import shutil
import struct
from collections.abc import Iterator
from pathlib import Path

STEREO_MODES = {"mono": 0, "top-bottom": 1, "side-by-side": 2}
"""The painting's stereo layouts (``camera.STEREO``) and their ``st3d`` stereo_mode."""
V1_STEREO = {"mono": "mono", "top-bottom": "top-bottom", "side-by-side": "left-right"}
V1_UUID = bytes.fromhex("ffcc8263f8554a938814587a02521fdd")
METADATA_SOURCE = "rcp (recursive camera painting)"
CONTAINERS = {b"moov", b"trak", b"mdia", b"minf", b"stbl"}  # boxes made only of boxes, on the way to stsd
CODEC_CONFIGS = {b"avcC", b"hvcC", b"av1C", b"vpcC"}  # st3d and sv3d follow these in the sample entry
VISUAL_SAMPLE_ENTRY = 8 + 78  # a VisualSampleEntry's header and fixed fields, before its child boxes
COPY_CHUNK = 1 << 20


class Mp4Error(ValueError):
    """A file whose boxes are not the MP4 this module can add the metadata to."""


def box(kind: bytes, payload: bytes) -> bytes:
    return struct.pack(">I4s", 8 + len(payload), kind) + payload


def full_box(kind: bytes, payload: bytes) -> bytes:
    return box(kind, bytes(4) + payload)  # version 0, flags 0


def v2_boxes(stereo: str) -> bytes:
    """``st3d`` then ``sv3d``, for an uncropped equirect picture in the stereo layout ``stereo``."""
    projection = box(b"proj", full_box(b"prhd", bytes(12)) + full_box(b"equi", bytes(16)))
    header = full_box(b"svhd", METADATA_SOURCE.encode() + b"\0")
    return full_box(b"st3d", bytes([STEREO_MODES[stereo]])) + box(b"sv3d", header + projection)


def v1_box(stereo: str) -> bytes:
    """The V1 ``uuid`` box: Google's spherical XML, as its injector writes it."""
    xml = (
        '<?xml version="1.0"?><rdf:SphericalVideo\n'
        'xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#"\n'
        'xmlns:GSpherical="http://ns.google.com/videos/1.0/spherical/">'
        "<GSpherical:Spherical>true</GSpherical:Spherical>"
        "<GSpherical:Stitched>true</GSpherical:Stitched>"
        f"<GSpherical:StitchingSoftware>{METADATA_SOURCE}</GSpherical:StitchingSoftware>"
        "<GSpherical:ProjectionType>equirectangular</GSpherical:ProjectionType>"
        f"<GSpherical:StereoMode>{V1_STEREO[stereo]}</GSpherical:StereoMode>"
        "</rdf:SphericalVideo>"
    )
    return box(b"uuid", V1_UUID + xml.encode())


def header(data: bytes | bytearray, at: int, room: int) -> tuple[bytes, int, int]:
    """The box header at ``data[at:]``: ``(type, header bytes, size)``, with ``room`` bytes left in its parent
    (a size of 0 means all of them)."""
    if len(data) - at < 8 or room < 8:
        raise Mp4Error(f"a box header is cut short at byte {at}")
    size, kind = struct.unpack_from(">I4s", data, at)
    if size == 1:
        if len(data) - at < 16:
            raise Mp4Error(f"a box header is cut short at byte {at}")
        return kind, 16, struct.unpack_from(">Q", data, at + 8)[0]
    return kind, 8, room if size == 0 else size


def boxes(data: bytes | bytearray, start: int, end: int) -> Iterator[tuple[bytes, int, int, int]]:
    """The boxes laid end to end in ``data[start:end]``: ``(type, offset, header bytes, size)`` each."""
    at = start
    while at < end:
        kind, head, size = header(data, at, end - at)
        if size < head or at + size > end:
            raise Mp4Error(f"the {kind!r} box at byte {at} claims {size} bytes, more than its parent holds")
        yield kind, at, head, size
        at += size


def top_level(file) -> list[tuple[bytes, int, int, int]]:
    """The file's top-level boxes, each ``(type, offset, header bytes, size)``, read header by header (the
    media itself is never read)."""
    end = file.seek(0, os.SEEK_END)
    found, at = [], 0
    while at < end:
        file.seek(at)
        kind, head, size = header(file.read(16), 0, end - at)
        if size < head or at + size > end:
            raise Mp4Error(f"the {kind!r} box at byte {at} claims {size} bytes, more than the file holds")
        found.append((kind, at, head, size))
        at += size
    return found


def add_spherical(src: Path, dst: Path, stereo: str = "mono") -> None:
    """Write to ``dst`` the MP4 ``src`` with the spherical metadata of an equirect picture laid out as
    ``stereo`` (a key of :data:`STEREO_MODES`) on its video track. Raises :class:`Mp4Error` for a file that
    is not such an MP4 (no ``moov``, no video track, one already spherical)."""
    if stereo not in STEREO_MODES:
        raise ValueError(f"stereo must be one of {', '.join(STEREO_MODES)}, got {stereo!r}")
    with open(src, "rb") as source:
        tops = top_level(source)
        moovs = [t for t in tops if t[0] == b"moov"]
        if len(moovs) != 1:
            raise Mp4Error(f"{src}: an MP4 has one moov box, this file has {len(moovs)}")
        _, moov_at, _, moov_size = moovs[0]
        source.seek(moov_at)
        moov = bytearray(source.read(moov_size))
        media_after = any(kind == b"mdat" and at > moov_at for kind, at, _, _ in tops)
        grown = with_metadata(moov, stereo, shift_chunks=media_after)
        with open(dst, "wb") as out:
            source.seek(0)
            copy(source, out, moov_at)
            out.write(grown)
            source.seek(moov_at + moov_size)
            shutil.copyfileobj(source, out, COPY_CHUNK)


def copy(source, out, count: int) -> None:
    while count > 0:
        chunk = source.read(min(count, COPY_CHUNK))
        if not chunk:
            raise Mp4Error("the file ended early")
        out.write(chunk)
        count -= len(chunk)


def with_metadata(moov: bytearray, stereo: str, shift_chunks: bool) -> bytearray:
    """``moov`` (the whole box) with the V2 boxes in its video sample entry and the V1 box in its video
    track; every chunk offset moved by the bytes added when ``shift_chunks`` (the media follows)."""
    trak = video_track(moov)
    stsd = descend(moov, trak, [b"mdia", b"minf", b"stbl", b"stsd"])
    entry_at = stsd[1] + stsd[2] + 8  # stsd: full box (4 bytes) and an entry count (4 bytes)
    kind, _, entry_header, entry_size = next(boxes(moov, entry_at, stsd[1] + stsd[3]))
    children = list(boxes(moov, entry_at + VISUAL_SAMPLE_ENTRY, entry_at + entry_size))
    if any(k in (b"st3d", b"sv3d") for k, *_ in children):
        raise Mp4Error(f"the {kind.decode(errors='replace')} sample entry already has spherical metadata")
    configs = [at + size for k, at, _, size in children if k in CODEC_CONFIGS]
    insert_at = configs[0] if configs else entry_at + entry_size
    holders = [entry_at, stsd[1], *ancestors(moov, stsd[1])]  # found before the bytes move
    v2, v1 = v2_boxes(stereo), v1_box(stereo)
    trak_end = trak[1] + trak[3]
    moov[trak_end:trak_end] = v1  # the later insertion first: the earlier offsets still hold
    moov[insert_at:insert_at] = v2
    for at in holders:  # each holds the sample entry; moov and the trak hold the V1 box too
        grow(moov, at, len(v2) + (len(v1) if at <= trak[1] else 0))
    if shift_chunks:
        for chunk_box in chunk_offsets(moov):
            shift(moov, chunk_box, len(v1) + len(v2))
    return moov


def video_track(moov: bytearray) -> tuple[bytes, int, int, int]:
    """The first ``trak`` whose handler (``mdia/hdlr``) is ``vide``."""
    for found in boxes(moov, 8, len(moov)):
        if found[0] != b"trak":
            continue
        hdlr = descend(moov, found, [b"mdia", b"hdlr"], required=False)
        if hdlr is not None and moov[hdlr[1] + hdlr[2] + 8 : hdlr[1] + hdlr[2] + 12] == b"vide":
            return found
    raise Mp4Error("the MP4 has no video track")


def descend(moov, parent, path: list[bytes], required: bool = True):
    """The box at ``path`` below ``parent`` (first of each type), or None when absent and not ``required``."""
    for kind in path:
        start, end = parent[1] + parent[2], parent[1] + parent[3]
        parent = next((b for b in boxes(moov, start, end) if b[0] == kind), None)
        if parent is None:
            if required:
                raise Mp4Error(f"the video track has no {kind.decode()} box")
            return None
    return parent


def ancestors(moov: bytearray, offset: int) -> list[int]:
    """The offsets of the container boxes (``moov`` down to ``stbl``) that hold the byte at ``offset``."""
    found, start, end = [0], 8, len(moov)
    while True:
        holder = next((b for b in boxes(moov, start, end) if b[1] <= offset < b[1] + b[3]), None)
        if holder is None or holder[0] not in CONTAINERS or holder[1] == offset:
            return found
        found.append(holder[1])
        start, end = holder[1] + holder[2], holder[1] + holder[3]


def grow(moov: bytearray, at: int, added: int) -> None:
    """The box at ``at`` is ``added`` bytes longer."""
    (size,) = struct.unpack_from(">I", moov, at)
    if size == 1:
        (large,) = struct.unpack_from(">Q", moov, at + 8)
        struct.pack_into(">Q", moov, at + 8, large + added)
    elif size == 0:
        raise Mp4Error("a box inside moov runs to the end of the file")
    else:
        struct.pack_into(">I", moov, at, size + added)


def chunk_offsets(moov: bytearray) -> Iterator[tuple[bytes, int, int, int]]:
    """Every ``stco`` and ``co64`` box of every track."""
    for trak in boxes(moov, 8, len(moov)):
        if trak[0] == b"trak":
            stbl = descend(moov, trak, [b"mdia", b"minf", b"stbl"], required=False)
            if stbl is not None:
                yield from (b for b in boxes(moov, stbl[1] + stbl[2], stbl[1] + stbl[3]) if b[0] in (b"stco", b"co64"))


def shift(moov: bytearray, chunk_box: tuple[bytes, int, int, int], added: int) -> None:
    """Move every chunk offset of an ``stco`` (32-bit) or ``co64`` (64-bit) box by ``added`` bytes."""
    kind, at, header, size = chunk_box
    (count,) = struct.unpack_from(">I", moov, at + header + 4)
    form = ">I" if kind == b"stco" else ">Q"
    width = struct.calcsize(form)
    first = at + header + 8
    if first + count * width > at + size:
        raise Mp4Error(f"the {kind.decode()} box holds fewer offsets than it counts")
    for k in range(count):  # one entry a chunk: a few hundred in a long video
        (offset,) = struct.unpack_from(form, moov, first + k * width)
        if kind == b"stco" and offset + added > 0xFFFFFFFF:
            raise Mp4Error("the video is too large for its 32-bit chunk offsets once the metadata is added")
        struct.pack_into(form, moov, first + k * width, offset + added)

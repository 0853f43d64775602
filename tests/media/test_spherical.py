"""The spherical-video metadata of an equirect painting's MP4: read back by a box walker of this file's own
(the V2 ``st3d``/``sv3d`` boxes in the video's sample entry, the V1 XML in its track) and by FFmpeg, whose
MP4 reader turns them into the frames' side data; the video's frames untouched by the boxes added."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import av
import numpy as np
import pytest
from helpers.scenes import SPINNING_BOX

from rcp_server.camera.camera import STEREO
from rcp_server.cli import main
from rcp_server.media import spherical
from rcp_server.media.video import Mp4Writer

WIDTH, HEIGHT = 64, 32
# AVSphericalMapping.projection and AVStereo3D.type, each the first int32 of its side data
FFMPEG_EQUIRECTANGULAR = 0
FFMPEG_STEREO = {"mono": 0, "side-by-side": 1, "top-bottom": 2}  # AV_STEREO3D_2D, _SIDEBYSIDE, _TOPBOTTOM


def frames(count=6) -> list[np.ndarray]:
    rng = np.random.default_rng(7)
    return [rng.random((HEIGHT, WIDTH, 3)).astype(np.float32) for _ in range(count)]


def write(out: Path, projection: str, stereo: str = "mono") -> Path:
    writer = Mp4Writer(out, WIDTH, HEIGHT, 12, projection, stereo)
    for image in frames():
        writer.write(image)
    writer.close()
    return out


# ---- an MP4 box walker of this test's own ----


def children(data: bytes) -> list[tuple[bytes, bytes]]:
    """``(type, payload)`` of the boxes laid end to end in ``data`` (32-bit sizes: all a small MP4 has)."""
    out, at = [], 0
    while at < len(data):
        size, kind = struct.unpack_from(">I4s", data, at)
        assert 8 <= size <= len(data) - at, f"{kind!r} at {at} claims {size} bytes"
        out.append((kind, data[at + 8 : at + size]))
        at += size
    return out


def child(data: bytes, kind: bytes) -> bytes:
    found = [payload for k, payload in children(data) if k == kind]
    assert len(found) == 1, f"{len(found)} {kind!r} boxes"
    return found[0]


def only_trak(moov: bytes) -> bytes:
    [trak] = [p for k, p in children(moov) if k == b"trak"]
    return trak


def read_metadata(file: Path):
    kinds = [k for k, _ in children(file.read_bytes())]
    moov = child(file.read_bytes(), b"moov")
    trak = only_trak(moov)
    stsd = child(child(child(child(trak, b"mdia"), b"minf"), b"stbl"), b"stsd")
    assert struct.unpack_from(">I", stsd, 4)[0] == 1  # one sample entry
    [(entry_kind, entry)] = children(stsd[8:])
    return kinds, trak, entry_kind, children(entry[78:])  # a VisualSampleEntry's fixed fields, then boxes


def side_data(file: Path) -> dict[str, bytes]:
    with av.open(str(file)) as container:
        frame = next(container.decode(video=0))
        return {sd.type.name: bytes(sd) for sd in frame.side_data}


def decoded(file: Path) -> list[np.ndarray]:
    with av.open(str(file)) as container:
        return [frame.to_ndarray(format="rgb24") for frame in container.decode(video=0)]


# ---- the tests ----


@pytest.mark.parametrize("stereo", ["mono", "top-bottom", "side-by-side"])
def test_an_equirect_video_carries_the_v2_boxes_and_the_v1_xml(tmp_path, stereo):
    out = write(tmp_path / "pano.mp4", "equirect", stereo)
    kinds, trak, entry_kind, boxes = read_metadata(out)
    assert kinds.index(b"moov") < kinds.index(b"mdat")  # the index still comes first: plays while it loads
    assert entry_kind == b"avc1"
    names = [k for k, _ in boxes]
    assert names[:3] == [b"avcC", b"st3d", b"sv3d"]  # right after the codec's configuration, st3d first
    st3d, sv3d = dict(boxes)[b"st3d"], dict(boxes)[b"sv3d"]
    assert st3d == bytes(4) + bytes([{"mono": 0, "top-bottom": 1, "side-by-side": 2}[stereo]])
    assert [k for k, _ in children(sv3d)] == [b"svhd", b"proj"]
    svhd = child(sv3d, b"svhd")
    assert svhd[:4] == bytes(4) and svhd.endswith(b"\0") and b"rcp" in svhd
    proj = child(sv3d, b"proj")
    assert child(proj, b"prhd") == bytes(4 + 12)  # version and flags, then the pose: yaw, pitch, roll 0
    assert child(proj, b"equi") == bytes(4 + 16)  # the whole sphere: nothing cropped on any side
    [v1] = [p for k, p in children(trak) if k == b"uuid"]
    assert v1[:16] == bytes.fromhex("ffcc8263f8554a938814587a02521fdd")
    xml = v1[16:].decode()
    layout = {"mono": "mono", "top-bottom": "top-bottom", "side-by-side": "left-right"}[stereo]
    for element in (
        "<GSpherical:Spherical>true</GSpherical:Spherical>",
        "<GSpherical:Stitched>true</GSpherical:Stitched>",
        "<GSpherical:ProjectionType>equirectangular</GSpherical:ProjectionType>",
        f"<GSpherical:StereoMode>{layout}</GSpherical:StereoMode>",
    ):
        assert element in xml
    # FFmpeg's MP4 reader, as players built on it do, finds a sphere and the stereo layout
    found = side_data(out)
    assert struct.unpack_from("<i", found["SPHERICAL"])[0] == FFMPEG_EQUIRECTANGULAR
    assert struct.unpack_from("<i", found["STEREO3D"])[0] == FFMPEG_STEREO[stereo]


def test_the_boxes_leave_every_frame_as_it_was(tmp_path):
    flat = decoded(write(tmp_path / "flat.mp4", "perspective"))
    for stereo in ("mono", "top-bottom"):
        pano = decoded(write(tmp_path / f"{stereo}.mp4", "equirect", stereo))
        assert len(pano) == len(flat) == 6
        for a, b in zip(pano, flat, strict=True):
            np.testing.assert_array_equal(a, b)  # every chunk offset moved by the bytes inserted before it


def test_a_perspective_video_is_a_flat_one(tmp_path):
    out = write(tmp_path / "flat.mp4", "perspective", "top-bottom")
    _, trak, _, boxes = read_metadata(out)
    assert not {b"st3d", b"sv3d"} & {k for k, _ in boxes}
    assert b"uuid" not in [k for k, _ in children(trak)]
    assert not {"SPHERICAL", "STEREO3D"} & set(side_data(out))
    assert list(tmp_path.iterdir()) == [out]  # nothing left beside it


def test_an_mp4_with_its_index_at_the_end_keeps_its_offsets(tmp_path):
    src = tmp_path / "late.mp4"
    with av.open(str(src), "w", format="mp4") as container:  # no faststart: moov after mdat
        stream = container.add_stream("libx264", rate=12)
        stream.width, stream.height, stream.pix_fmt = WIDTH, HEIGHT, "yuv420p"
        for image in frames():
            container.mux(stream.encode(av.VideoFrame.from_ndarray((image * 255).astype(np.uint8), format="rgb24")))
        container.mux(stream.encode(None))
    dst = tmp_path / "late-pano.mp4"
    spherical.add_spherical(src, dst, "side-by-side")
    kinds, _, _, boxes = read_metadata(dst)
    assert kinds.index(b"mdat") < kinds.index(b"moov")
    assert dict(boxes)[b"st3d"][-1] == 2
    for a, b in zip(decoded(dst), decoded(src), strict=True):
        np.testing.assert_array_equal(a, b)


def test_every_stereo_layout_of_the_camera_has_its_boxes():
    assert set(spherical.STEREO_MODES) == set(STEREO) == set(spherical.V1_STEREO)


def test_what_cannot_take_the_metadata_is_refused(tmp_path):
    out = write(tmp_path / "pano.mp4", "equirect")
    with pytest.raises(spherical.Mp4Error, match="already has spherical metadata"):
        spherical.add_spherical(out, tmp_path / "twice.mp4")
    text = tmp_path / "not.mp4"
    text.write_bytes(b"this is no video, just some text")
    with pytest.raises(spherical.Mp4Error):
        spherical.add_spherical(text, tmp_path / "x.mp4")
    with pytest.raises(ValueError, match="stereo must be one of mono, top-bottom, side-by-side"):
        spherical.add_spherical(out, tmp_path / "x.mp4", "anaglyph")
    with pytest.raises(ValueError, match="no video of projection 'fisheye'"):
        Mp4Writer(tmp_path / "f.mp4", WIDTH, HEIGHT, 12, "fisheye")


def test_rcp_render_paints_a_360_video_of_a_path(tmp_path):
    scene, path = tmp_path / "tiny.toml", tmp_path / "walk.json"
    scene.write_text(SPINNING_BOX)
    keys = [{"t": 0, "eye": [0, 1, 4], "look_at": [0, 1, 0]}, {"t": 0.5, "eye": [1, 1, 3], "look_at": [0, 1, 0]}]
    path.write_text(json.dumps({"fps": 4, "keyframes": keys}))
    out = tmp_path / "pano.mp4"
    argv = ["-q", "render", str(scene), "--path", str(path), "--out", str(out), "--width", "32", "--height", "16"]
    assert main([*argv, "--projection", "equirect", "--stereo", "side-by-side"]) == 0
    _, _, _, boxes = read_metadata(out)
    assert dict(boxes)[b"st3d"][-1] == 2  # left-right
    frames = decoded(out)
    assert len(frames) == 3 and frames[0].shape == (16, 64, 3)  # two eyes of 32x16, side by side

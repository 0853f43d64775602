"""A frame painted in bands, drawn by the client in a real Chromium: each band in place at its rows, shown once all
are in, and the picture is the frame painted whole (up to each band's own JPEG)."""

from __future__ import annotations

import base64
import io

import numpy as np
from helpers.browser import needs_chromium
from PIL import Image

from rcp_server.painting.loop import paint
from rcp_server.settings.params import PaintParams
from rcp_server.util import images

pytestmark = needs_chromium

W, H = 160, 90
BANDS = [(0, 30), (30, 30), (60, 30)]

DRAW = """async ([meta, parts]) => {
    const { FrameParts, decodeFrame } = await import("/bands.js");
    const gathered = new FrameParts();
    gathered.expect(meta);
    const buffers = parts.map((b64) => Uint8Array.from(atob(b64), (c) => c.charCodeAt(0)).buffer);
    const early = buffers.slice(0, -1).map((part) => gathered.take(part));  // not a frame until the last band
    const [whole, jpegs] = gathered.take(buffers[buffers.length - 1]);
    const bitmap = await decodeFrame(whole, jpegs);
    const canvas = new OffscreenCanvas(bitmap.width, bitmap.height);
    canvas.getContext("2d").drawImage(bitmap, 0, 0);
    const blob = await canvas.convertToBlob({ type: "image/png" });
    const bytes = new Uint8Array(await blob.arrayBuffer());
    let text = "";
    for (const byte of bytes) text += String.fromCharCode(byte);
    return { early, png: btoa(text) };
}"""


def test_bands_drawn_in_place_are_the_frame_painted_whole(browser, busy_scene, live_server):
    whole = images.to_uint8(paint(busy_scene, busy_scene.camera, W, H, PaintParams(iterations=2)).image)
    jpegs = [images.encode(whole[y : y + rows], "JPEG", 95) for y, rows in BANDS]
    meta = {"type": "frame", "width": W, "height": H, "bands": [list(band) for band in BANDS]}
    page = browser.new_page()
    page.goto(f"{live_server.url}/bands.js")  # the server's origin: the module imports from it
    drawn = page.evaluate(DRAW, [meta, [base64.b64encode(j).decode() for j in jpegs]])
    page.close()
    assert drawn["early"] == [None, None]  # shown only once all its bands are in
    picture = np.asarray(Image.open(io.BytesIO(base64.b64decode(drawn["png"]))).convert("RGB"))
    assert picture.shape == (H, W, 3)
    # each band exactly where it belongs: its own JPEG, decoded, at its rows
    bands = np.concatenate([np.asarray(Image.open(io.BytesIO(j)).convert("RGB")) for j in jpegs], axis=0)
    assert np.abs(picture.astype(np.int16) - bands).max() <= 2  # one JPEG decoder against another
    # and the frame painted whole, up to the JPEG's own loss
    assert np.abs(picture.astype(np.int16) - whole).mean() < 3

"""Uploading a model through the browser client (real Chromium, real server): pick a file, watch it upload,
walk through it; drop one on the page; find it again after a reload."""

from __future__ import annotations

import trimesh
from helpers.browser import canvas, client, needs_chromium, wait_final

pytestmark = needs_chromium

DROP = """([name, text]) => {
    const data = new DataTransfer();
    data.items.add(new File([text], name));
    for (const type of ["dragenter", "dragover", "drop"]) {
        window.dispatchEvent(new DragEvent(type, { dataTransfer: data, bubbles: true, cancelable: true }));
    }
}"""


def red_box() -> bytes:
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    box.visual.face_colors = [230, 20, 20, 255]
    return box.export(file_type="glb")


def test_a_model_picked_in_the_page_uploads_with_progress_and_is_walked_through(browser, live_server):  # noqa: F811
    with client(browser, live_server.url) as page:
        before = wait_final(page)["seq"]  # the default scene at rest: no more of its frames come after this
        page.set_input_files(
            "#upload-file", files=[{"name": "Red Box.glb", "mimeType": "model/gltf-binary", "buffer": red_box()}]
        )
        page.wait_for_function("rcp.state.scene?.uploaded === true", timeout=30_000)
        scene = page.evaluate("rcp.state.scene")
        assert scene["title"] == "Red Box" and scene["triangles"] == 12 and scene["name"].startswith("u-")
        wait_final(page, after_seq=before)
        image = canvas(page).astype(int)
        height, width, _ = image.shape
        red, green, blue = image[height // 2, width // 2]
        assert red > green + 60 and red > blue + 60  # the box, in the middle of the view
        assert abs(image[5, 5] - image[5, width - 5]).sum() < 30  # the backdrop around it
        assert page.text_content("#upload-status") == "Red Box: 12 triangles"
        assert page.is_hidden("#upload-progress")
        assert page.evaluate("[...document.querySelectorAll('#scene optgroup option')].map((o) => o.value)") == [
            scene["name"]
        ]
        assert f"scene={scene['name']}" in page.url
        # a dropped file that is no model is refused in the page, and the walk-through stays
        page.evaluate(DROP, ["notes.txt", "hello"])
        assert "not a model this server reads" in page.evaluate("rcp.state.errors.at(-1)")
        assert page.evaluate("rcp.state.scene.name") == scene["name"]
        # the page remembers its uploads: a reload opens the scene again and lists it
        page.reload()
        wait_final(page)
        assert page.evaluate("rcp.state.scene.name") == scene["name"]
        assert page.evaluate("rcp.uploads.group.children.length") == 1


def test_a_models_other_cameras_are_offered_as_viewpoints(browser, live_server):  # noqa: F811
    from helpers.gltf import GltfBuilder

    b = GltfBuilder()
    b.quad([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], material=b.material())
    b.camera("Front", (0, 0, 4))
    b.camera("Far away", (0, 0, 12), yfov_degrees=20)
    with client(browser, live_server.url) as page:
        wait_final(page)
        assert page.is_hidden("#viewpoint-row")  # the village brings no cameras of its own
        page.set_input_files(
            "#upload-file", files=[{"name": "cams.glb", "mimeType": "model/gltf-binary", "buffer": b.glb()}]
        )
        page.wait_for_function("rcp.state.scene?.uploaded === true", timeout=30_000)
        assert page.is_visible("#viewpoint-row")
        options = page.evaluate("[...document.querySelectorAll('#viewpoint option')].map((o) => o.textContent)")
        assert options == ["the scene's camera", "Far away"]
        page.select_option("#viewpoint", label="Far away")
        assert page.evaluate("rcp.walk.walk.eye") == [0, 0, 12]
        page.click("#reset-camera")
        assert page.evaluate("rcp.walk.walk.eye") == [0, 0, 4] and page.input_value("#viewpoint") == ""

"""``rcp bench restart``: what a restart costs a stored upload, against real ``rcp serve`` processes.

An upload's first load (the sandbox reads the file, the server builds its tree) and its first frame; then the
server is killed (``kill -9``) and started again on the same data folder: the time from the new process to
``/api/health`` and to the stored upload's first frame, against the same start on an empty data folder (the
interpreter, the scenes and the compiled kernels, which every start pays). Health is polled every 0.2 s.
"""

from __future__ import annotations

import json
import re
import tempfile
import time
import urllib.request
import uuid
from pathlib import Path

from ..service.loopback import TIMEOUT, rcp_serve, request


def model_bytes(triangles: int) -> tuple[str, bytes]:
    """A GLB built in code: a sphere of about ``triangles`` triangles (icospheres of 20 x 4^k)."""
    import trimesh

    subdivisions = 0
    while 20 * 4 ** (subdivisions + 1) <= triangles:
        subdivisions += 1
    return "sphere.glb", trimesh.creation.icosphere(subdivisions=subdivisions).export(file_type="glb")


def upload(url: str, filename: str, data: bytes) -> dict:
    """``POST /api/scenes`` as multipart form data, with the standard library."""
    boundary = uuid.uuid4().hex
    body = (
        (
            f'--{boundary}\r\nContent-Disposition: form-data; name="file"; filename="{filename}"\r\n'
            "Content-Type: application/octet-stream\r\n\r\n"
        ).encode()
        + data
        + f"\r\n--{boundary}--\r\n".encode()
    )
    asked = urllib.request.Request(
        f"{url}/api/scenes", body, {"content-type": f"multipart/form-data; boundary={boundary}"}, method="POST"
    )
    with urllib.request.urlopen(asked, timeout=10 * TIMEOUT) as answer:
        return json.loads(answer.read())


def first_frame(url: str, name: str, width: int, height: int) -> float:
    clock = time.monotonic()
    answer = request(f"{url}/api/render", {"scene": name, "width": width, "height": height}, timeout=10 * TIMEOUT)
    if answer.status != 200:
        raise RuntimeError(f"render of {name}: {answer.status} {answer.body[:200]!r}")
    return time.monotonic() - clock


def bench_restart(model: Path | None, triangles: int, width: int, height: int) -> None:
    filename, data = (model.name, model.read_bytes()) if model is not None else model_bytes(triangles)
    with tempfile.TemporaryDirectory(prefix="rcp-bench-restart-") as work:
        folder, empty = Path(work) / "data", Path(work) / "empty"
        clock = time.monotonic()
        with rcp_serve(Path(work), data=str(empty)):
            bare = time.monotonic() - clock
        with rcp_serve(Path(work), data=str(folder)) as served:
            clock = time.monotonic()
            info = upload(served.url, filename, data)
            loaded = time.monotonic() - clock
            drawn = first_frame(served.url, info["name"], width, height)
            served.process.kill()  # kill -9
            served.process.wait()
        clock = time.monotonic()
        with rcp_serve(Path(work), data=str(folder)) as served:
            up = time.monotonic() - clock
            first_frame(served.url, info["name"], width, height)
            serving = time.monotonic() - clock
            said = re.search(r"kept from the last run, loaded in ([\d.]+) s", served.log.read_text())
            reload = float(said.group(1)) if said else float("nan")
    size = len(data) / 1e6
    print(
        f"rcp bench restart: {filename}, {info['triangles']:,} triangles, {size:.1f} MB; first frames {width}x{height}"
    )
    print(f"  dropped model: upload read and built {loaded:6.2f} s, then its first frame {drawn:6.2f} s")
    print(f"  restart (kill -9), stored upload: healthy after {up:6.2f} s, its first frame at {serving:6.2f} s")
    print(f"  the same start on an empty data folder: healthy after {bare:6.2f} s")
    print(
        f"  the stored upload's reload, as the server logs it: {reload:6.2f} s (its first load above: {loaded:.2f} s)"
    )

"""What the service shares: its settings, the scenes (loaded once, at startup), the workshop and the open
walk-throughs; and the dependency that hands it to a route, typed (``service: ServiceDep``)."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Protocol, TypeGuard, TypeVar

from fastapi import Depends
from starlette.applications import Starlette
from starlette.requests import HTTPConnection

from ..camera.wire import spec_of
from ..painting import warmup
from ..scene.scene import Scene, material_names, object_names
from ..scene.scenefile import SceneError, load_scene, scene_names
from . import protocol
from .memory import Budget, GiveBack, default_memory_bytes
from .painter import LocalPainter, Painter
from .prints import Prints
from .settings import Settings
from .startup import Startup
from .store import Store
from .uploads import Upload, Uploads, stored_scene
from .videos import Videos
from .workshop import Workshop

if TYPE_CHECKING:  # for the annotation only: a server opens a RayPainter (and Ray loads) only when told to use Ray
    from ..cluster.port import RayPort
    from ..cluster.remote import RemoteRay, RemoteWalks

log = logging.getLogger("rcp.service")

FIRST_SCENE = "default"  # the scene the page opens (client/main.js): its kernels compile before the service is ready
T = TypeVar("T")


class Walkthrough(Protocol):
    """An open walk-through, as the service sees it (``session.Session``): one it can close, showing a scene."""

    @property
    def scene(self) -> Scene | None:
        """The scene it shows, None before hello."""
        ...

    @property
    def walking(self) -> bool:
        """It has said hello: it holds one of the ``max_sessions`` places."""
        ...

    def close(self) -> None: ...


@dataclass
class Service:
    """What every request and session shares: settings, the scenes (and their descriptions, made once so a
    listing never builds geometry on the event loop), the workshop, the open walk-throughs."""

    settings: Settings
    scenes: dict[str, Scene]
    infos: dict[str, protocol.SceneInfo]
    workshop: Workshop
    videos: Videos
    store: Store  # the data folder (RCP_DATA): uploads and videos kept across restarts
    painter: Painter  # who paints walk frames, renders and films: here, or on Ray (chosen once, in open)
    prints: Prints | None = None  # stills at print size, painted in the background (opened with the service)
    sessions: set[Walkthrough] = field(default_factory=set)
    uploads: Uploads = field(default_factory=Uploads)  # visitors' scenes, apart from the operator's
    startup: Startup = field(
        default_factory=Startup
    )  # ready once the scenes are loaded, the first one's kernels compiled
    memory: Budget = field(default_factory=lambda: Budget(default_memory_bytes()))  # the paintings' (memory.py)
    give_back: GiveBack = field(default_factory=GiveBack)  # the memory of walks that closed, to the system
    closed: bool = False
    _closing: threading.Lock = field(default_factory=threading.Lock)  # the start's last steps, or the close

    @classmethod
    def open(cls, settings: Settings) -> Service:
        """Blocking, and quick: take the data folder (:class:`~.store.DataFolderError` if another server has it),
        join Ray when told to (:class:`~rcp_server.cluster.painter.ClusterError` if it does not answer in bounded
        time) and open the workshop. The rest, slow on a first start, is :meth:`start`'s."""
        store = Store(settings.data)
        painter: Painter | None = None
        workshop = None
        try:
            workshop = Workshop(settings.threads, settings.max_renders, settings.max_waiting)
            give_back = GiveBack()
            painter = open_painter(settings, workshop, give_back)
            memory = Budget(settings.memory_bytes)
            videos = Videos(settings, workshop, store, painter, memory)
            service = cls(settings, {}, {}, workshop, videos, store, painter, memory=memory, give_back=give_back)
            service.prints = Prints(settings, workshop, memory, store.folder / "prints", videos.disk_used)
            return service
        except BaseException:
            for opened in (painter, workshop, store):
                if opened is not None:
                    opened.close()
            raise

    def start(self) -> threading.Thread:
        """In a thread, while the server already answers (``startup.py``): load the scenes of ``settings.scenes``,
        compile the kernels the first scene's walk needs, load the stored uploads and resume the stored video
        jobs; then the service is ready, and the same thread compiles the other paintings' kernels. A fault
        there is logged, and the service serves what did load."""
        thread = threading.Thread(target=self._start, name="rcp-start", daemon=True)  # a compile cannot be stopped
        thread.start()
        return thread

    def _start(self) -> None:
        startup, clock = self.startup, time.monotonic()
        try:
            scenes = load_scenes(self.settings.scenes)
            self.infos.update({name: scene_info(scene) for name, scene in scenes.items()})
            self.scenes.update(scenes)
            log.info("serving %d scenes: %s", len(scenes), ", ".join(scenes))
            loaded, entries = time.monotonic(), warmup.kernels()
            startup.enter("compiling kernels", lambda: (warmup.compiled(entries), len(entries)))
            first = scenes.get(FIRST_SCENE) or next(iter(scenes.values()), None)
            if first is not None:
                _compile_ahead(warmup.first_frame, first)
            compiled = time.monotonic()
            if on_ray(self.painter) and self.settings.ray_walks:
                startup.enter("measuring a walk frame on Ray")
                walks = open_walks(self.settings, self.painter.cluster, scenes)
                with self._closing:
                    if self.closed:
                        walks.close()
                        return
                    self.painter.walks = walks
            startup.enter("loading uploads")
            with self._closing:
                if self.closed:
                    return
                self.store.remove_strays()
                self.uploads = load_uploads(self.settings, self.store)
                self.videos.resume(self.scene)
            log.info(
                "ready in %.1f s (scenes %.1f s, kernels %.1f s)",
                time.monotonic() - clock,
                loaded - clock,
                compiled - loaded,
            )
        except Exception:
            log.exception("the start did not finish: serving what it loaded")
        finally:
            startup.finish()
        self._compile_the_rest()

    def _compile_the_rest(self) -> None:
        """After the start, while the service serves: the kernels of the other scenes and of the image-space
        method (a painting that needs one before waits for the compiler instead)."""
        clock = time.monotonic()
        if not self.closed and _compile_ahead(warmup.warm, list(self.scenes.values())):
            log.info("the other paintings' kernels compiled in %.1f s", time.monotonic() - clock)

    def walking(self) -> int:
        """Walk-throughs that have said hello (a WebSocket that has not holds no place)."""
        return sum(session.walking for session in self.sessions)

    def scene(self, name: str) -> Scene | None:
        """The scene a name stands for, the operator's or an uploaded one: the lookup of every route and
        message that takes a scene name."""
        found = self.scenes.get(name)
        if found is None and (upload := self.uploaded(name)) is not None:
            found = upload.scene
        return found

    def unknown_scene(self, name: str) -> str:
        """What a caller is told for a name :meth:`scene` does not know (the operator's names only: an uploaded
        scene's name is its holder's secret)."""
        return f"unknown scene {name!r}; known: {', '.join(sorted(self.scenes))}"

    def info(self, name: str) -> protocol.SceneInfo | None:
        """The description of the scene ``name`` stands for (as :meth:`scene` finds it)."""
        found = self.infos.get(name)
        if found is None and (upload := self.uploaded(name)) is not None:
            found = upload.info
        return found

    def uploaded(self, name: str) -> Upload | None:
        """The uploaded scene ``name``, marked as used, after removing the idle ones; None if there is none."""
        self.sweep_uploads()
        return self.uploads.get(name)

    def sweep_uploads(self) -> None:
        """Removes the uploaded scenes nobody has used for ``upload_idle_s`` (shown in a walk-through is used)."""
        in_use = [*(session.scene for session in self.sessions), *self.videos.scenes_in_progress()]
        self.uploads.sweep(self.settings.upload_idle_s, in_use)

    def close(self) -> None:
        """Close every walk-through (their paintings stop at the next iteration), then the workshop."""
        with self._closing:  # a start still under way loads no uploads nor resumes videos after this
            self.closed = True
        for session in list(self.sessions):
            session.close()
        self.workshop.stop()  # the video jobs' paintings stop at their next tile
        self.videos.close()
        if self.prints is not None:
            self.prints.close()
        self.painter.close()
        self.workshop.close()
        self.give_back.close()
        self.uploads.flush()
        self.store.close()


def open_painter(settings: Settings, workshop: Workshop, give_back: GiveBack | None = None) -> Painter:
    """The service's painter, chosen once: on this machine's threads, or with ``RCP_RAY_ADDRESS`` on Ray (joined
    now, before serving: healthy means Ray is there; :class:`~rcp_server.cluster.painter.ClusterError` if it does
    not answer in bounded time), which paints here what Ray cannot paint now."""
    local = LocalPainter(workshop, give_back)
    if settings.ray_address is None:
        return local
    from ..cluster.port import RayPort
    from ..cluster.remote import RemoteRay

    # Ray's driver runs in a child process: the server outlives its cluster
    cluster = RemoteRay(settings.ray_address, walk_target(settings), settings.walk_retry_s)
    try:
        cluster.start(settings.ray_join_s)
    except BaseException:
        cluster.close()
        raise
    return RayPort(cluster, local, settings.ray_min_work)


def on_ray(painter: Painter) -> TypeGuard[RayPort]:
    """Whether the service paints on Ray: asked once, at start-up, to place the walkers there too."""
    return hasattr(painter, "cluster")


def walk_target(settings: Settings):
    """What each walker on Ray is admitted for (None: walks are not painted on Ray)."""
    from ..cluster.admission import Target

    if not settings.ray_walks:
        return None
    return Target(1000.0 / settings.frame_ms, settings.walk_width, settings.walk_height)


def open_walks(settings: Settings, cluster: RemoteRay, scenes: dict[str, Scene]) -> RemoteWalks:
    """The walkers' place on Ray (past its room, on the server's own cores), with the cost of a ray measured there
    on the first scene (when that fails, it is measured again with the first walker's frame)."""
    from ..cluster.remote import RemoteWalks

    walks = RemoteWalks(cluster, max(1, settings.threads), settings.walk_retry_s)
    for scene in list(scenes.values())[:1]:
        try:
            measured = walks.calibrate(scene, scene.painting({}))
            frame_s, ray_s = measured["frame_s"], measured["ray_s"]
            log.info(
                "walkers on Ray, measured: %.2f ms a frame and %.3g us a ray of CPU; %s",
                frame_s * 1e3,
                ray_s * 1e6,
                measured["describe"],
            )
        except Exception as exc:  # Ray answers, but not yet for this: the first walker measures it
            log.warning("walkers on Ray: %s", exc)
    return walks


def scene_info(scene: Scene) -> protocol.SceneInfo:
    return protocol.SceneInfo(
        name=scene.name,
        title=scene.title,
        camera=spec_of(scene.camera),
        viewpoints=[protocol.Viewpoint(name=name, camera=spec_of(c)) for name, c in scene.viewpoints.items()],
        motions=list(scene.motions),
        paint=scene.paint.non_defaults(),
        objects=object_names(scene.objects),
        materials=material_names(scene.objects),
        animated=scene.animated,
        triangles=scene.geometry(0.0)[0].face_count,
    )


def load_uploads(settings: Settings, store: Store) -> Uploads:
    """The uploads the store keeps, loaded from their parsed arrays; those idle past ``upload_idle_s`` (time
    passes while a server is down) or past the count and memory budgets (the most recently used kept first)
    are removed, as are any that no longer load. A scene that a stored video job still paints is in use."""
    uploads = Uploads(store=store)
    now, weight, clock = time.time(), 0, time.monotonic()
    filming = {r.scene for r in store.videos() if r.state in ("queued", "running")}  # in use: a film goes on
    for record in sorted(store.uploads(), key=lambda r: (r.name in filming, r.used), reverse=True):
        if record.name in filming:
            record = record.model_copy(update={"used": now})
        over = len(uploads.scenes) >= settings.upload_max_scenes or weight + record.weight > settings.upload_total_bytes
        if now - record.used > settings.upload_idle_s or over:
            log.info("upload %s removed: %s", record.name, "over a budget" if over else "idle")
            store.remove_upload(record.name)
            continue
        try:
            folder, limits = store.upload_dir(record.name), settings.upload_limits()
            scene = stored_scene(folder, record.name, record.title, limits, settings.upload_total_bytes)
        except Exception as exc:
            log.error("upload %s removed: it no longer loads (%s)", record.name, exc)
            store.remove_upload(record.name)
            continue
        uploads.keep(scene, scene_info(scene).model_copy(update={"uploaded": True}), record)
        weight += record.weight
    if uploads.scenes:
        log.info(
            "%d uploaded scenes kept from the last run, loaded in %.2f s", len(uploads.scenes), time.monotonic() - clock
        )
    return uploads


def _compile_ahead(warm: Callable[[T], None], scenes: T) -> bool:
    """``warm(scenes)``; False, logged, where it fails: the kernels then compile at the first painting that
    needs them instead, slower but not broken."""
    try:
        warm(scenes)
    except Exception:
        log.exception("the kernels could not be compiled ahead")
        return False
    return True


def load_scenes(folder: Path) -> dict[str, Scene]:
    """Every scene of ``folder``, ready to trace; a broken one is reported and skipped."""
    scenes = {}
    for name in scene_names(folder):
        try:
            scene = load_scene(name, folder)
            scene.geometry(0.0)  # build its BVH now, not on the first request
            scenes[name] = scene
        except SceneError as exc:
            log.error("scene %s skipped: %s", name, exc)
        except Exception:  # a fault the scene file's checks did not foresee: still only this scene's
            log.exception("scene %s skipped: it failed to build", name)
    return scenes


def service_of(app: Starlette) -> Service | None:
    """The service an app serves, None before its lifespan has opened it."""
    return getattr(app.state, "service", None)


async def get_service(connection: HTTPConnection) -> Service:
    """The dependency of HTTP and WebSocket routes alike (both are an ``HTTPConnection``). Async, so that
    FastAPI calls it on the event loop: a plain function would take a worker thread for every request."""
    service = service_of(connection.app)
    assert service is not None, "a route ran before the app's lifespan opened the service"
    return service


ServiceDep = Annotated[Service, Depends(get_service)]

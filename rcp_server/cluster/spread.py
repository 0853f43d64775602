"""A walker's crew reserved by a Ray placement group: a bundle a band actor, one a node.

The nodes a walker paints on are dealt by :func:`~.admission.crews` (fairly among walkers); its group reserves one
bundle on each of them (``STRICT_SPREAD``, each bundle held to its node by Ray's ``ray.io/node-id`` label), and each
band actor is started in its node's bundle (the autoscaler is asked for nodes apart, by the walkers' resource
requests: a bundle held to a node is no demand for a new one).

The group is built and awaited on a thread, never on a frame's path: meanwhile the members already warm paint. A
node lost leaves the crew at once (the frame is painted again by the others); the group, which still holds a
bundle on the lost node, is rebuilt on a thread for the nodes that remain, the members move into it (a new actor
warms beside the old one, which paints until then) and the old group is removed once nobody lives in it. A walker
that leaves removes its groups with its crew.

A bundle reserves ``BUNDLE_MEMORY`` of a node's memory and no CPU: a walker's cores are counted by admission (its
share), and CPU held here would starve the films' crew, whose actors take whole CPUs.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

from .connection import first_line, ray_module

log = logging.getLogger("rcp")

BUNDLE_MEMORY = 64 << 20  # bytes a band actor's bundle reserves: a walk actor's scene and band state, small scenes
READY_S = 30.0  # a group not placed within this is removed, and built again at the next frame
SETTLE_S = 3.0  # members move into a new group this long after it was placed, one at a time: a node just lost
# leaves the crew's CPUs busy (the frame painted again, Ray's own recovery), and a successor warming beside a band
# actor slows its band
NODE_LABEL = "ray.io/node-id"  # the label Ray gives every node: its id


class Seat:
    """A bundle of a placement group: where one band actor starts (Ray's scheduling strategy for it)."""

    def __init__(self, group: Any, index: int):
        self.group = group
        self.index = index

    @property
    def group_id(self) -> str:
        return self.group.id.hex()

    def strategy(self) -> Any:
        from ray.util.scheduling_strategies import PlacementGroupSchedulingStrategy

        return PlacementGroupSchedulingStrategy(self.group, placement_group_bundle_index=self.index)


class Spread:
    """One walker's placement groups: the one its members live in (ready), the one being built for the nodes it is
    dealt now, and older ones that still hold members (removed once they hold none). ``off`` once Ray cannot pin a
    bundle to a node (an old Ray): the crew is then placed by node affinity alone."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.group: Any = None  # the ready group new members start in
        self.nodes: dict[str, int] = {}  # node -> its bundle in ``group``
        self._wanted: tuple[str, ...] = ()  # the nodes of the group held or being built
        self._groups: dict[str, Any] = {}  # every group made and not removed, by id
        self._building: set[str] = set()  # groups still waiting to be placed (they remove themselves if stale)
        self.built = 0  # groups placed so far
        self.placed_at = 0.0  # when the ready group was placed (monotonic)
        self.off = False
        self.closed = False

    def want(self, nodes: list[str]) -> None:
        """The crew is dealt ``nodes``: a group over them is built on a thread unless it is held or being built."""
        key = tuple(sorted(nodes))
        with self._lock:
            if self.off or self.closed or not key or key == self._wanted:
                return
            self._wanted = key
            if self.group is not None and key == tuple(sorted(self.nodes)):
                return
        threading.Thread(target=self._build, args=(key,), name="rcp-ray-crew-group", daemon=True).start()

    def seat(self, node: str) -> Seat | None:
        """Where a member on ``node`` starts: its bundle in the ready group; None while no group holds the node."""
        with self._lock:
            index = self.nodes.get(node)
            return None if index is None else Seat(self.group, index)

    def settled(self) -> bool:
        """Whether members of older groups may move into the ready one now (``SETTLE_S`` after it was placed)."""
        return time.monotonic() - self.placed_at > SETTLE_S

    def release(self, living: set[str]) -> None:
        """Remove (on a thread) the groups, other than the ready one, that no member lives in (``living``: ids)."""
        with self._lock:
            keep = set(living) | self._building | ({self.group.id.hex()} if self.group is not None else set())
            idle = [self._groups.pop(gid) for gid in list(self._groups) if gid not in keep]
        if idle:
            threading.Thread(target=_remove, args=(idle,), name="rcp-ray-crew-group-gone", daemon=True).start()

    def _build(self, nodes: tuple[str, ...]) -> None:
        ray = ray_module()
        from ray.util import placement_group, placement_group_table

        try:
            group = placement_group(
                [{"memory": BUNDLE_MEMORY}] * len(nodes),
                strategy="STRICT_SPREAD",
                bundle_label_selector=[{NODE_LABEL: node} for node in nodes],
            )
        except TypeError:  # a Ray without label selectors: the crew is placed by node affinity alone
            log.warning("this Ray cannot hold a placement group's bundles to nodes: crews placed by node affinity")
            self.off = True
            return
        except Exception as exc:  # Ray went meanwhile: built again at a later frame
            log.info("a walker's placement group was not made: %s", first_line(exc))
            self._forget(nodes)
            return
        gid = group.id.hex()
        with self._lock:
            self._groups[gid] = group
            self._building.add(gid)
        try:
            placed = bool(ray.wait([group.ready()], timeout=READY_S)[0])
            table = placement_group_table(group) if placed else {}
        except Exception as exc:
            log.info("a walker's placement group was not placed: %s", first_line(exc))
            placed, table = False, {}
        with self._lock:
            self._building.discard(gid)
            fresh = placed and not self.closed and self._wanted == nodes
            if fresh:
                self.group, self.built, self.placed_at = group, self.built + 1, time.monotonic()
                self.nodes = {node: int(index) for index, node in table["bundles_to_node_id"].items()}
            else:
                self._groups.pop(gid, None)
                if self._wanted == nodes:  # not placed in time: the next frame asks again
                    self._wanted = ()
        if not fresh:
            _remove([group])

    def _forget(self, nodes: tuple[str, ...]) -> None:
        with self._lock:
            if self._wanted == nodes:
                self._wanted = ()

    def close(self) -> None:
        """Remove every group (the walker left; its actors are stopped with them)."""
        with self._lock:
            self.closed = True
            groups, self._groups = list(self._groups.values()), {}
            self.group, self.nodes = None, {}
        _remove(groups)


def _remove(groups: list) -> None:
    ray = ray_module()
    if not ray.is_initialized():  # Ray stopped, and the groups with it
        return
    from ray.util import remove_placement_group

    for group in groups:
        try:
            remove_placement_group(group)
        except Exception:  # gone already, or Ray with it: nothing left to remove
            pass

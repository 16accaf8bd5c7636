"""The map on the Zenoh bus: :class:`MapNode` answers ``map/rooms``, ``map/places``,
``map/edges``, ``map/add`` and ``map/connect`` under ``toploc/<robot_id>/`` from a map database
file; :class:`~toploc.bus.clients.mapdb.MapClient` (also importable from here) is what a client
uses to talk to it.

- ``map/rooms`` -> ``{"rooms": [{"id", "name", "n_places"}]}``
- ``map/places`` (optional ``{"room": name}``) -> ``{"places": [Place fields]}``; positions in
  metres and headings in degrees in the frame of the place's room.
- ``map/edges`` -> ``{"edges": [[room_a, room_b]]}`` (the undirected room graph)
- ``map/add``: payload the panorama as PNG bytes, attachment ``{"kind": "add", "room",
  "x_m"?, "y_m"?, "heading_deg"?, "leg_from"?, "leg_via"?}`` (a place recorded on a drive:
  the place before it, and the odometry positions ``[[x_m, y_m], ...]`` between them, see
  :class:`mapdb.records.Leg`) -> ``{"place_id", "room", "new", "fingerprints":
  {detector: n}, "refresh_after_s"}``. The image is checked (at most ``max_image_bytes``, a PNG
  of at most ``max_image_pixels`` by its header) before it is decoded; each detector the map
  holds is extracted (:func:`toploc.extraction.extract_image`, the path of ``toploc map add``)
  and the place written with its fingerprints in one transaction. The same image again is
  answered with its place (``new`` false).
- ``map/connect``: ``{"kind": "connect", "room_a", "room_b"}`` -> ``{"room_a", "room_b",
  "added"}``; both rooms must exist.

Each read opens the file read-only for its own duration, each write writable: zenoh runs each
queryable on a thread of its own and an ``sqlite3`` connection may only be used by the thread
that made it; a map rebuilt while the node runs is thus served fresh. A map error (a read-only
map, a lock) becomes an error reply and nothing is written.

- ``map/changed`` (publication, after each write, before its reply): ``{"kind": "changed",
  "what": "add" | "connect", "stamp"}`` (a site robot's replicator publishes ``"what":
  "replica"`` on the same key). A localizer in this process or another one reloads its map when
  it hears it (:func:`~toploc.bus.clients.mapdb.subscribe_changes`,
  :class:`toploc.service.MapRefresher`): it reads the same SQLite file, so a map node and a
  localizer node in two processes need the same file (one machine, or shared storage).
"""

from __future__ import annotations

import hashlib
import logging
import math
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import zenoh

from localizer.panorama_io import decode_grey
from mapdb.database import MapDatabase
from mapdb.errors import DuplicatePlaceError, MapDatabaseError, UnknownPlaceError, UnknownRoomError
from mapdb.records import Leg, NewPlace, Place, check_name
from mapdb.replica import MAX_CHANGES, read_changes, read_snapshot
from mapdb.replication import CHUNK_BYTES, encode_changes, encode_snapshot, sha256_hex, split_chunks
from toploc import bus
from toploc.bus.clients.mapdb import ADD_TIMEOUT_S, MapClient, subscribe_changes
from toploc.bus.png_codec import check_png
from toploc.bus.schemas import (
    ADD,
    ADDED,
    CHANGED,
    CHANGES_BATCH,
    CHANGES_QUERY,
    CONNECT,
    CONNECTED,
    EDGES,
    MAP_VERSION,
    PLACES,
    PLACES_QUERY,
    ROOMS,
    SNAPSHOT_CHUNK,
)
from toploc.limits import Limits
from toploc.nodes.node import Node

__all__ = ["ADD_TIMEOUT_S", "NODE_NAME", "MapClient", "MapNode", "subscribe_changes"]

NODE_NAME = "mapdb"
_log = logging.getLogger(__name__)


def _json_safe(fields: dict[str, Any]) -> dict[str, Any]:
    """``fields`` with non-finite numbers as None (JSON null): a map written before non-finite
    poses were refused may hold one, and strict JSON has no NaN or inf."""
    return {
        name: None if isinstance(value, float) and not math.isfinite(value) else value
        for name, value in fields.items()
    }


def _named(where: str, field: str, error: ValueError) -> bus.BusMessageError:
    return bus.BusMessageError(f"{where}: field {field!r}: {error}")


def _check_same_place(where: str, stored: Place, sent: NewPlace) -> None:
    """Raise BusMessageError unless ``sent`` (the same image as ``stored``) names its room and
    pose: the same image under two rooms or poses is a conflict, not a repeat."""
    stored_pose = (stored.x_m, stored.y_m, stored.heading_deg)
    sent_pose = (sent.x_m, sent.y_m, sent.heading_deg)
    if stored.room != sent.room or stored_pose != sent_pose:
        raise bus.BusMessageError(
            f"{where}: this image is already place {stored.id} of room {stored.room!r} at "
            f"{stored_pose}; it was sent for room {sent.room!r} at {sent_pose}: nothing added"
        )


class MapNode(Node):
    """Serve the map at ``db_path`` on the bus within ``limits``; ``close()`` (or ``with``).

    ``camera``: the ``--camera`` text the panoramas of ``map/add`` are read with.
    ``detectors``: what ``map/add`` extracts when the map holds no fingerprint yet (otherwise
    each detector the map holds). After each write ``map/changed`` is published.
    ``refresh_after_s``: told in the ``map/add`` reply (when the localizer uses the place).
    ``read_only``: why the node refuses every write (``map/add``, ``map/connect``) with that
    error reply, e.g. toploc's built-in map; None: it writes.
    ``map_id``: serve the site map of this id (its keys and the replication keys; the file's
    own id must be it, :func:`check_site_map`). ``forward_to``: the site map id whose map node
    takes this node's writes (``db_path`` is then a replica of it). ``chunk_bytes``: the most
    bytes of a snapshot in one reply.
    """

    def __init__(
        self,
        session: zenoh.Session,
        robot_id: str,
        db_path: Path | str,
        limits: Limits | None = None,
        camera: str = "auto",
        detectors: tuple[str, ...] = ("sift",),
        refresh_after_s: float | None = None,
        read_only: str | None = None,
        map_id: str | None = None,
        forward_to: str | None = None,
        chunk_bytes: int = CHUNK_BYTES,
    ) -> None:
        super().__init__(session, robot_id, NODE_NAME, map_id)
        self.read_only = read_only
        self.forward_to = forward_to
        self.chunk_bytes = chunk_bytes
        self.db_path = Path(db_path)
        self.limits = limits or Limits()
        self.camera = camera
        self.detectors = detectors
        self.refresh_after_s = refresh_after_s
        k = self.key
        self._changes = session.declare_publisher(k(bus.MAP_CHANGED))
        self.entities += [
            self._changes,
            bus.serve(session, k(bus.MAP_ROOMS), self._on_rooms),
            bus.serve(session, k(bus.MAP_PLACES), self._on_places),
            bus.serve(session, k(bus.MAP_EDGES), self._on_edges),
            bus.serve_binary(session, k(bus.MAP_ADD), self._on_add),
            bus.serve(session, k(bus.MAP_CONNECT), self._on_connect),
        ]
        if map_id is not None:
            check_site_map(self.db_path, map_id)
            self.entities += [
                bus.serve(session, k(bus.SITE_VERSION), self._on_version),
                bus.serve_replies(session, k(bus.SITE_SNAPSHOT), self._on_snapshot),
                bus.serve(session, k(bus.SITE_CHANGES), self._on_changes),
            ]
        self.entities.append(session.liveliness().declare_token(self.alive_key()))

    def _open(self) -> MapDatabase:
        return MapDatabase.open(self.db_path, readonly=True)

    def _on_rooms(self, _payload: bytes | None) -> bus.Reply:
        with self._open() as map_db:
            rooms = [asdict(room) for room in map_db.rooms()]
        return bus.Reply(ROOMS.encode({"rooms": rooms}))

    def _on_places(self, payload: bytes | None) -> bus.Reply:
        room = None
        if payload:
            limits = self.limits
            request = PLACES_QUERY.decode(
                self.key(bus.MAP_PLACES),
                payload,
                check_kind=False,
                max_bytes=limits.max_request_bytes,
                max_string_chars=limits.max_string_chars,
            )
            if "room" in request:
                PLACES_QUERY.check_optional(self.key(bus.MAP_PLACES), request)
                room = request["room"]
        with self._open() as map_db:
            places = [_json_safe(asdict(place)) for place in map_db.places(room)]
        return bus.Reply(PLACES.encode({"places": places}))

    def _on_edges(self, _payload: bytes | None) -> bus.Reply:
        with self._open() as map_db:
            edges = [list(edge) for edge in map_db.edges()]
        return bus.Reply(EDGES.encode({"edges": edges}))

    def _open_writable(self, where: str) -> MapDatabase:
        if self.read_only is not None:
            raise bus.BusMessageError(f"{where}: {self.read_only}")
        try:
            return MapDatabase.open(self.db_path, create=False)
        except MapDatabaseError as error:
            raise bus.BusMessageError(
                f"{where}: the map cannot be written, nothing was added ({error})"
            ) from None

    def _changed(self, what: str, map_db: MapDatabase) -> None:
        message: dict[str, Any] = {"what": what, "stamp": time.time()}
        map_id = map_db.map_id()
        if map_id is not None:
            message.update(version=map_db.map_version(), map_id=map_id)
        self._changes.put(CHANGED.encode(message))

    def _forward(self, suffix: str, payload: bytes | None, attachment: bytes | None) -> bus.Reply:
        """Pass a write on to the site map's node (``forward_to``); its reply."""
        assert self.forward_to is not None
        key_expr = bus.site_key(self.forward_to, suffix)
        sample = bus.request(self.session, key_expr, payload, ADD_TIMEOUT_S, attachment)
        return bus.Reply(sample.payload.to_bytes())

    def _on_version(self, _payload: bytes | None) -> bus.Reply:
        with self._open() as map_db:
            fields = {"map_id": map_db.map_id(), "version": map_db.map_version()}
        return bus.Reply(MAP_VERSION.encode({**fields, "stamp": time.time()}))

    def _on_snapshot(self, _payload: bytes | None) -> list[bus.Reply]:
        with self._open() as map_db:
            snapshot = read_snapshot(map_db)
        data = encode_snapshot(snapshot)
        chunks = split_chunks(data, self.chunk_bytes)
        head = {"map_id": snapshot.map_id, "version": snapshot.version, "n_chunks": len(chunks),
                "total_bytes": len(data), "sha256": sha256_hex(data)}  # fmt: skip
        _log.info("snapshot of version %d: %d bytes in %d chunk(s)", snapshot.version,
                  len(data), len(chunks))  # fmt: skip
        return [
            bus.Reply(chunk, SNAPSHOT_CHUNK.encode({**head, "index": i}))
            for i, chunk in enumerate(chunks)
        ]

    def _on_changes(self, payload: bytes | None) -> bus.Reply:
        where = self.key(bus.SITE_CHANGES)
        request = CHANGES_QUERY.decode(where, payload, True, self.limits.max_request_bytes)
        with self._open() as map_db:
            map_id = str(map_db.map_id())
            changes = read_changes(map_db, request["after"], MAX_CHANGES)
            version = map_db.map_version()
        last = changes[-1].version if changes else request["after"]
        head = {"map_id": map_id, "version": version, "more": last < version}
        return bus.Reply(encode_changes(map_id, changes), CHANGES_BATCH.encode(head))

    def _decode_metadata(self, where: str, attachment: bytes | None) -> dict[str, Any]:
        """The checked metadata of a ``map/add`` request (the attachment)."""
        limits = self.limits
        meta = ADD.decode(
            f"{where} (attachment)",
            attachment,
            True,
            limits.max_request_bytes,
            limits.max_string_chars,
        )
        ADD.check_optional(where, meta)
        try:
            check_name(meta["room"])
        except ValueError as error:
            raise _named(where, "room", error) from None
        if (meta.get("x_m") is None) != (meta.get("y_m") is None):
            raise bus.BusMessageError(f"{where}: give both 'x_m' and 'y_m', or neither")
        if meta.get("leg_via") is not None and meta.get("leg_from") is None:
            raise bus.BusMessageError(f"{where}: 'leg_via' needs 'leg_from'")
        if meta.get("leg_from") is not None and meta.get("x_m") is None:
            raise bus.BusMessageError(
                f"{where}: a place with 'leg_from' needs its odometry position 'x_m', 'y_m'"
            )
        return meta

    @staticmethod
    def _leg(where: str, meta: dict[str, Any]) -> Leg | None:
        """The :class:`Leg` a ``map/add`` request names, if any (BusMessageError if malformed)."""
        if meta.get("leg_from") is None:
            return None
        via = meta.get("leg_via") or []
        try:
            return Leg(meta["leg_from"], tuple(tuple(point) for point in via))
        except (TypeError, ValueError) as error:
            raise _named(where, "leg_via" if via else "leg_from", ValueError(str(error))) from None

    def _on_add(self, payload: bytes | None, attachment: bytes | None) -> bus.Reply:
        from toploc.extraction import extract_image, map_overrides

        where = self.key(bus.MAP_ADD)
        meta = self._decode_metadata(where, attachment)
        if self.forward_to is not None:
            return self._forward(bus.MAP_ADD, payload, attachment)
        data = check_png(where, payload, self.limits.max_image_bytes)
        image = decode_grey(data, where, self.limits.max_image_pixels)
        sha = hashlib.sha256(data).hexdigest()
        leg = self._leg(where, meta)
        place = NewPlace(
            room=meta["room"],
            image_sha256=sha,
            source=f"{where} sha256:{sha[:12]}",
            x_m=meta.get("x_m"),
            y_m=meta.get("y_m"),
            heading_deg=meta.get("heading_deg"),
            captured_utc=None,
            leg=leg,
        )
        with self._open_writable(where) as map_db:
            presets = tuple(map_db.fingerprint_counts()) or self.detectors
            fingerprints = extract_image(image, presets, self.camera, map_overrides(map_db))
            try:
                place_id, new = map_db.add_place(place, fingerprints), True
            except DuplicatePlaceError as error:
                place_id, new = error.place_id, False
                _check_same_place(where, map_db.place(place_id), place)
            except UnknownPlaceError as error:  # the leg's first place
                raise _named(where, "leg_from", ValueError(str(error))) from None
            except ValueError as error:  # a leg from a place without a position
                raise _named(where, "leg_from", error) from None
            if new:
                self._changed("add", map_db)
        _log.info(
            "map add: place %d in room %s (%s; features %s)", place_id, place.room,
            "new" if new else "already in the map",
            ", ".join(f"{f.detector} {f.n}" for f in fingerprints),
        )  # fmt: skip
        reply = {
            "place_id": place_id,
            "room": place.room,  # the stored one: a repeat must name the same room
            "new": new,
            "fingerprints": {f.detector: f.n for f in fingerprints},
            "refresh_after_s": self.refresh_after_s,
        }
        return bus.Reply(ADDED.encode(reply))

    def _on_connect(self, payload: bytes | None) -> bus.Reply:
        where = self.key(bus.MAP_CONNECT)
        limits = self.limits
        request = CONNECT.decode(
            where, payload, True, limits.max_request_bytes, limits.max_string_chars
        )
        for field in ("room_a", "room_b"):
            try:
                check_name(request[field])
            except ValueError as error:
                raise _named(where, field, error) from None
        if request["room_a"] == request["room_b"]:
            raise bus.BusMessageError(
                f"{where}: cannot connect room {request['room_a']!r} to itself"
            )
        if self.forward_to is not None:
            return self._forward(bus.MAP_CONNECT, payload, None)
        with self._open_writable(where) as map_db:
            try:
                added = map_db.connect_rooms(request["room_a"], request["room_b"])
            except UnknownRoomError as error:
                field = "room_a" if error.room == request["room_a"] else "room_b"
                raise bus.BusMessageError(
                    f"{where}: field {field!r}: unknown room {error.room!r} (add a place in it "
                    "first)"
                ) from None
            if added:
                self._changed("connect", map_db)
        if added:
            _log.info("map connect: %s -- %s", request["room_a"], request["room_b"])
        reply = {"room_a": request["room_a"], "room_b": request["room_b"], "added": added}
        return bus.Reply(CONNECTED.encode(reply))


def check_site_map(db_path: Path, map_id: str) -> None:
    """Make sure the map at ``db_path`` is site map ``map_id``: a map whose id is still the
    automatic one (``map-`` and 12 hex digits, never served under a name) is named ``map_id``;
    a map named otherwise is a :class:`MapDatabaseError` (its replicas know it by that name)."""
    with MapDatabase.open(db_path, create=False) as map_db:
        held = map_db.map_id()
        if held == map_id:
            return
        if held is not None and _is_automatic_id(held):
            map_db.set_map_id(map_id)
            _log.info("map %s named %s (its id was %s)", db_path, map_id, held)
            return
    raise MapDatabaseError(
        f"map {db_path} is site map {held!r}, not {map_id!r}: serve it with --map-id {held} "
        "(replicas know it by that id)",
        db_path,
    )


def _is_automatic_id(map_id: str) -> bool:
    digits = map_id.removeprefix("map-")
    return len(digits) == 12 and all(c in "0123456789abcdef" for c in digits)

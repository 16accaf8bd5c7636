"""A site's shared map (``toploc/map/<map_id>/``): :class:`SiteMapClient` adds to it and reads
what a replica needs (its version, its snapshot in chunks, the changes after a version) from
the :class:`~toploc.nodes.mapdb.MapNode` that serves it; :func:`subscribe_site_changes` follows
its ``changed``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import zenoh

from mapdb.replication import BadMapDataError, join_chunks
from toploc import bus
from toploc.bus.clients.mapdb import MapClient
from toploc.bus.schemas import CHANGED, CHANGES_BATCH, CHANGES_QUERY, MAP_VERSION, SNAPSHOT_CHUNK

SNAPSHOT_TIMEOUT_S = 60.0
"""How long :meth:`SiteMapClient.snapshot` waits for every chunk."""


def subscribe_site_changes(
    session: zenoh.Session, map_id: str, on_change: Callable[[int | None], None]
) -> zenoh.Subscriber:
    """Call ``on_change(version)`` for each well-formed ``changed`` of site map ``map_id``
    (``version`` None if the message has none); undeclare the subscriber to stop."""

    def read(key_expr: str, data: bytes) -> dict[str, Any]:
        message = CHANGED.decode(key_expr, data)
        CHANGED.check_optional(key_expr, message)
        return message

    return bus.subscribe(
        session, bus.site_key(map_id, bus.MAP_CHANGED), read,
        lambda message: on_change(message.get("version")),
    )  # fmt: skip


class SiteMapClient(MapClient):
    """:class:`MapClient`'s calls (``add``, ``connect``, ``places``) on site map ``map_id``,
    and the replication queries. Raises :class:`~toploc.bus.BusTimeout` if no map node answers,
    :class:`~toploc.bus.BusReplyError` with its message for an error reply,
    :class:`~toploc.bus.BusMessageError` for a reply that is not what it should be."""

    def __init__(
        self,
        session: zenoh.Session,
        map_id: str,
        timeout_s: float = bus.DEFAULT_TIMEOUT_S,
        snapshot_timeout_s: float = SNAPSHOT_TIMEOUT_S,
    ) -> None:
        super().__init__(session, bus.FALLBACK_ROBOT_ID, timeout_s)
        self.map_id = bus.check_map_id(map_id)
        self.snapshot_timeout_s = snapshot_timeout_s

    def key(self, suffix: str) -> str:
        """``toploc/map/<map_id>/<suffix>`` (:func:`toploc.bus.keys.site_key`)."""
        return bus.site_key(self.map_id, suffix)

    def version(self) -> int:
        """The map's current version (its id checked to be this client's)."""
        key_expr = self.key(bus.SITE_VERSION)
        reply = bus.request_json(self.session, key_expr, MAP_VERSION.fields, None, self.timeout_s)
        self._check_id(key_expr, reply["map_id"])
        return int(reply["version"])

    def snapshot(self) -> tuple[bytes, int]:
        """The encoded snapshot (:func:`mapdb.replication.encode_snapshot`), its chunks joined
        and checked against their SHA-256, and its version."""
        key_expr = self.key(bus.SITE_SNAPSHOT)
        samples = bus.request_all(self.session, key_expr, None, self.snapshot_timeout_s)
        chunks: dict[int, bytes] = {}
        heads = set()
        for sample in samples:
            attachment = None if sample.attachment is None else sample.attachment.to_bytes()
            head = SNAPSHOT_CHUNK.decode(f"{key_expr} (attachment)", attachment)
            self._check_id(key_expr, head["map_id"])
            heads.add((head["version"], head["n_chunks"], head["sha256"]))
            chunks[head["index"]] = sample.payload.to_bytes()
        if len(heads) != 1:
            raise bus.BusMessageError(f"{key_expr}: chunks of {len(heads)} snapshots mixed")
        ((version, n_chunks, sha256),) = heads
        try:
            data = join_chunks(chunks, n_chunks, sha256, f"{key_expr}: the snapshot")
        except BadMapDataError as error:
            raise bus.BusMessageError(str(error)) from None
        return data, version

    def changes(self, after: int) -> tuple[bytes, int, bool]:
        """The encoded changes after version ``after`` (:func:`mapdb.replication.
        encode_changes`), the map's current version, and whether more follow."""
        key_expr = self.key(bus.SITE_CHANGES)
        payload = CHANGES_QUERY.encode({"after": after})
        sample = bus.request(self.session, key_expr, payload, self.timeout_s)
        attachment = None if sample.attachment is None else sample.attachment.to_bytes()
        head = CHANGES_BATCH.decode(f"{key_expr} (attachment)", attachment)
        self._check_id(key_expr, head["map_id"])
        return sample.payload.to_bytes(), int(head["version"]), bool(head["more"])

    def _check_id(self, key_expr: str, map_id: str) -> None:
        if map_id != self.map_id:
            raise bus.BusMessageError(f"{key_expr}: the reply is of map {map_id!r}, not this one")

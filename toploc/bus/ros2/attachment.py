"""The attachment rmw_zenoh puts on every sample, request and reply (rmw_zenoh
``docs/design.md``, "Publishers", "Service Clients", "Service Servers"; written by
``AttachmentData::serialize_to_zbytes`` in ``attachment_helpers.cpp`` with Zenoh's own
serializer): 33 bytes,

- the sequence number, int64 little-endian;
- the source timestamp, int64 little-endian, nanoseconds since the UNIX epoch;
- the GID's length, one byte (always 16);
- the GID of the publisher, or of the client (a request, and the reply to it), 16 bytes.

An rmw_zenoh subscription drops a sample without it; a reply echoes the request's sequence
number and client GID, which is how the client matches it to its request. Zenoh's serializer
(``zenoh.ext.z_serialize``) writes exactly these bytes, as zenoh-cpp's does.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import zenoh
from zenoh.ext import Int64, ZDeserializeError, z_deserialize, z_serialize

GID_BYTES = 16
ATTACHMENT_BYTES = 8 + 8 + 1 + GID_BYTES


@dataclass(frozen=True)
class Attachment:
    """What rides with a ROS 2 message over rmw_zenoh: ``sequence_number`` (a publisher's count
    from 1, or the client's request number), ``source_timestamp_ns`` (ns since the UNIX epoch)
    and the 16-byte ``gid`` of the publisher or client."""

    sequence_number: int
    source_timestamp_ns: int
    gid: bytes

    def __post_init__(self) -> None:
        if len(self.gid) != GID_BYTES:
            raise ValueError(f"a GID is {GID_BYTES} bytes, got {len(self.gid)}")

    def to_bytes(self) -> bytes:
        """The 33 bytes of the attachment."""
        data = z_serialize(
            (Int64(self.sequence_number), Int64(self.source_timestamp_ns), bytes(self.gid))
        )
        return data.to_bytes()

    @classmethod
    def from_bytes(cls, data: bytes | None) -> Attachment:
        """Read an attachment; ``ValueError`` naming what is wrong (none, short, a GID that is
        not 16 bytes)."""
        if data is None:
            raise ValueError("no attachment (rmw_zenoh sends 33 bytes: sequence number, "
                             "timestamp, GID)")  # fmt: skip
        if len(data) != ATTACHMENT_BYTES:
            raise ValueError(f"the attachment is {len(data)} bytes, not {ATTACHMENT_BYTES}")
        try:
            seq, stamp, gid = z_deserialize(tuple[Int64, Int64, bytes], zenoh.ZBytes(data))
        except ZDeserializeError as error:
            raise ValueError(f"the attachment does not decode: {error}") from None
        return cls(int(seq), int(stamp), bytes(gid))

    def reply(self, now_ns: int | None = None) -> Attachment:
        """The attachment of the reply to a request with this one: the request's sequence number
        and client GID, the time of the reply."""
        return Attachment(self.sequence_number, now_ns or time.time_ns(), self.gid)

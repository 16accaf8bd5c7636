"""The JSON codec of the bus: the envelope every JSON message shares, and field checks.

Every JSON message is an object ``{"schema": SCHEMA_VERSION, "kind": <kind>, ...fields}``; an
error reply (``Query.reply_err``) is ``{"schema": 1, "kind": "error", "error": "<message>"}``.
Binary payloads (the PNG panorama, :mod:`toploc.bus.png_codec`) carry their metadata as a JSON
attachment with the same envelope. Each message's kind and fields are declared once, in
:mod:`toploc.bus.schemas`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

from toploc.bus.errors import BusMessageError

SCHEMA_VERSION = 1

FieldType = type | tuple[type, ...]


def encode(kind: str, payload: Mapping[str, Any]) -> bytes:
    """``{"schema": SCHEMA_VERSION, "kind": kind, **payload}`` as UTF-8 JSON (strict: no NaN)."""
    clash = {"schema", "kind"} & set(payload)
    if clash:
        raise ValueError(f"{kind} message: field(s) {sorted(clash)} are reserved for the envelope")
    try:
        text = json.dumps({"schema": SCHEMA_VERSION, "kind": kind, **payload}, allow_nan=False)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{kind} message cannot be encoded as JSON: {error}") from error
    return text.encode()


def encode_message(message: Mapping[str, Any]) -> bytes:
    """A message that carries its own envelope (``schema`` and ``kind``, e.g.
    ``RoomBelief.to_json()``) as UTF-8 JSON; ``ValueError`` for another schema or no kind."""
    kind = message.get("kind")
    if message.get("schema") != SCHEMA_VERSION or not isinstance(kind, str):
        raise ValueError(
            f"a message needs schema {SCHEMA_VERSION} and a kind, got schema "
            f"{message.get('schema')!r} and kind {kind!r}"
        )
    return encode(kind, {k: v for k, v in message.items() if k not in ("schema", "kind")})


def _type_name(expected: FieldType) -> str:
    types = expected if isinstance(expected, tuple) else (expected,)
    return " or ".join("null" if t is type(None) else t.__name__ for t in types)


def has_type(value: Any, expected: FieldType) -> bool:
    """JSON-aware isinstance: an int is a float, a bool is not a number, floats must be finite."""
    types = expected if isinstance(expected, tuple) else (expected,)
    for t in types:
        if t is type(None) and value is None:
            return True
        if isinstance(value, bool) and t is not bool:
            continue
        if t is float and isinstance(value, int | float):
            return math.isfinite(value)
        if t is not type(None) and isinstance(value, t):
            return True
    return False


def check_fields(where: str, message: Mapping[str, Any], required: Mapping[str, FieldType]) -> None:
    """Raise :class:`BusMessageError` (prefixed ``where``) for a missing or ill-typed field."""
    for name, expected in required.items():
        if name not in message:
            raise BusMessageError(f"{where}: missing field {name!r} ({_type_name(expected)})")
        value = message[name]
        if not has_type(value, expected):
            raise BusMessageError(
                f"{where}: field {name!r} must be {_type_name(expected)}, got {value!r}"
            )


def _longest_string(value: Any) -> int:
    """The length of the longest string (key or value) anywhere in a parsed JSON ``value``."""
    if isinstance(value, str):
        return len(value)
    if isinstance(value, dict):
        return max((max(len(k), _longest_string(v)) for k, v in value.items()), default=0)
    if isinstance(value, list):
        return max((_longest_string(v) for v in value), default=0)
    return 0


def decode(
    key_expr: str,
    data: bytes | None,
    required: Mapping[str, FieldType] | None = None,
    kind: str | None = None,
    max_bytes: int | None = None,
    max_string_chars: int | None = None,
) -> dict[str, Any]:
    """Parse a JSON message received on ``key_expr`` and check its envelope and fields.

    ``required`` maps field name to type (``float`` accepts JSON integers; ``(dict, type(None))``
    allows null). Raises :class:`BusMessageError` naming the key: larger than ``max_bytes``, not
    UTF-8 JSON, not an object, a string longer than ``max_string_chars``, wrong ``schema``
    version, wrong ``kind`` (if given), missing or ill-typed field.
    """
    if data is None or len(data) == 0:
        raise BusMessageError(f"{key_expr}: empty payload, expected a JSON object")
    if max_bytes is not None and len(data) > max_bytes:
        raise BusMessageError(
            f"{key_expr}: payload is {len(data)} bytes; at most {max_bytes} are accepted"
        )
    try:
        message = json.loads(bytes(data).decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        preview = bytes(data[:40])
        raise BusMessageError(
            f"{key_expr}: payload is not JSON ({error}; starts {preview!r})"
        ) from None
    if not isinstance(message, dict):
        raise BusMessageError(
            f"{key_expr}: payload must be a JSON object, got {type(message).__name__}"
        )
    if max_string_chars is not None and _longest_string(message) > max_string_chars:
        raise BusMessageError(
            f"{key_expr}: a string of {_longest_string(message)} characters; at most "
            f"{max_string_chars} are accepted"
        )
    schema = message.get("schema")
    if schema != SCHEMA_VERSION or isinstance(schema, bool):
        raise BusMessageError(
            f"{key_expr}: schema version {schema!r}, this toploc speaks {SCHEMA_VERSION}"
        )
    if kind is not None and message.get("kind") != kind:
        raise BusMessageError(
            f"{key_expr}: message kind {message.get('kind')!r}, expected {kind!r}"
        )
    check_fields(key_expr, message, required or {})
    return message


def error_payload(message: str, retry_after_s: float | None = None) -> bytes:
    """The body of an error reply: ``{"schema": 1, "kind": "error", "error": message}``, with
    ``"retry_after_s"`` when the refusal is for now only (a rate limit)."""
    fields: dict[str, Any] = {"error": message}
    if retry_after_s is not None:
        fields["retry_after_s"] = float(retry_after_s)
    return encode("error", fields)

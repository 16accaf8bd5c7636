"""ROS 2 names and their Zenoh key expressions, as rmw_zenoh maps them (rmw_zenoh
``docs/design.md``, "Topic and Service name mapping to Zenoh key expressions").

A topic or service of fully qualified name ``/ns/name`` and type ``pkg/msg/Type`` is the key
``<domain_id>/ns/name/pkg::msg::dds_::Type_/<RIHS01 type hash>``: the domain keeps graphs of
different ``ROS_DOMAIN_ID`` apart, the type name and hash keep endpoints of different types
apart. (Humble has no type hashes: there the last chunk is ``TypeHashNotSupported``; toploc
speaks Jazzy's and later.)
"""

from __future__ import annotations

import re

SLASH_REPLACEMENT = "%"
"""What stands for ``/`` in a mangled name (a liveliness token's namespace, topic, enclave)."""
MAX_DOMAIN_ID = 232
"""The largest ROS domain id (the ROS 2 documentation's "The ROS_DOMAIN_ID": 0 to 232)."""

_NAME_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_TYPE_NAME = re.compile(r"([A-Za-z][A-Za-z0-9_]*)/(msg|srv)/([A-Z][A-Za-z0-9]*)")


def check_domain_id(domain_id: int) -> int:
    """``domain_id`` if it is a ROS domain id (an int from 0 to 232), else ``ValueError``."""
    if isinstance(domain_id, bool) or not isinstance(domain_id, int):
        raise ValueError(f"ROS domain id must be an integer, got {domain_id!r}")
    if not 0 <= domain_id <= MAX_DOMAIN_ID:
        raise ValueError(f"ROS domain id must be 0 to {MAX_DOMAIN_ID}, got {domain_id}")
    return domain_id


def _check_tokens(what: str, name: str, tokens: list[str]) -> None:
    bad = [token for token in tokens if not _NAME_TOKEN.fullmatch(token) or "__" in token]
    if bad:
        raise ValueError(
            f"{what} {name!r}: {bad[0]!r} is not a ROS name token (letters, digits and single "
            "underscores, not starting with a digit)"
        )


def check_namespace(namespace: str) -> str:
    """The namespace as ROS writes it: absolute, no trailing slash (``/`` for none);
    ``ValueError`` for one that is not a ROS namespace (``robot1`` reads as ``/robot1``)."""
    text = "/" + namespace.strip("/") if namespace.strip("/") else "/"
    if text != "/":
        _check_tokens("namespace", namespace, text[1:].split("/"))
    return text


def check_node_name(name: str) -> str:
    """``name`` if it is a ROS node name (one name token), else ``ValueError``."""
    _check_tokens("node name", name, [name])
    return name


def fully_qualified_name(namespace: str, node: str, name: str) -> str:
    """The fully qualified name of ``name`` (ROS's "Topic and Service Names"): ``~/x`` is
    private to the node (``/<namespace>/<node>/x``), ``/x`` absolute, ``x`` relative to the
    namespace."""
    ns = check_namespace(namespace)
    base = ns.rstrip("/")
    if name.startswith("~/"):
        full = f"{base}/{check_node_name(node)}/{name[2:]}"
    elif name.startswith("/"):
        full = name
    else:
        full = f"{base}/{name}"
    _check_tokens("topic or service name", name, full[1:].split("/"))
    return full


def mangle(name: str) -> str:
    """``name`` with each ``/`` as ``%`` (rmw_zenoh's ``mangle_name``), for one key chunk."""
    return name.replace("/", SLASH_REPLACEMENT)


def dds_type_name(type_name: str) -> str:
    """The DDS name of a ROS type: ``std_msgs/msg/String`` -> ``std_msgs::msg::dds_::String_``
    (a service ``std_srvs/srv/Trigger`` -> ``std_srvs::srv::dds_::Trigger_``)."""
    match = _TYPE_NAME.fullmatch(type_name)
    if match is None:
        raise ValueError(f"ROS type name must be like 'std_msgs/msg/String', got {type_name!r}")
    package, kind, name = match.groups()
    return f"{package}::{kind}::dds_::{name}_"


def data_key(domain_id: int, full_name: str, type_name: str, type_hash: str) -> str:
    """The key expression of a topic or service: ``<domain>/<full name without its leading
    slash>/<DDS type name>/<type hash>``."""
    if not full_name.startswith("/") or full_name.endswith("/"):
        raise ValueError(f"a fully qualified name starts with '/', got {full_name!r}")
    domain = check_domain_id(domain_id)
    return f"{domain}/{full_name[1:]}/{dds_type_name(type_name)}/{type_hash}"

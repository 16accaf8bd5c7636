"""A site's Zenoh files: the router's access control with one user per robot, and each user's
client file (``toploc site access``; docs/security.md, "A site").

Zenoh's ACL names users, not robot ids, and released Zenoh has no rule templated on the user
name, so a rule per robot is written out here: robot ``r1`` logs in as user ``r1`` and may serve
``toploc/r1/**`` only; it uses its own keys and the site maps' keys. The map node alone serves
the site maps' keys. An operator may ask any robot and map anything (belief, localize, drive)
and serves nothing; a viewer subscribes to everything and may only query what reads (a belief,
odometry, a map's rooms, places, edges and version). Anyone else logged in gets nothing
through the router. Zenoh matches a message to a rule when the message's key expression is
included in the rule's (``toploc/*/localizer/belief`` covers ``toploc/r1/localizer/belief``).

Pure: dictionaries that a JSON5 file holds (JSON is JSON5), and the credentials text.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from toploc.bus.keys import (
    BASE_ODOM,
    LOCALIZER_BELIEF,
    MAP_EDGES,
    MAP_PLACES,
    MAP_ROOMS,
    ROOT,
    SITE_VERSION,
    check_map_id,
    check_robot_id,
    site_key,
)

SERVE = ["declare_queryable", "reply", "put", "liveliness_token"]
"""The messages a node sends to serve keys: its queryables and replies, publications, tokens."""
USE = ["query", "declare_subscriber", "liveliness_query", "declare_liveliness_subscriber"]
"""The messages a client sends to use keys: queries, subscriptions, liveliness checks."""
SUBSCRIBE = ["declare_subscriber", "liveliness_query", "declare_liveliness_subscriber"]
READ_SUFFIXES = (LOCALIZER_BELIEF, BASE_ODOM, MAP_ROOMS, MAP_PLACES, MAP_EDGES)
"""A robot's keys whose queries only read (a viewer's)."""

_USER_NAME = re.compile(r"[A-Za-z0-9._-]+")


@dataclass(frozen=True)
class SiteUsers:
    """Who logs in to a site's router: the map node's user, one user per robot (its robot id),
    operators and viewers (user names)."""

    robots: tuple[str, ...]
    map_node: str = "map-node"
    operators: tuple[str, ...] = ()
    viewers: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not self.robots:
            raise ValueError("a site needs at least one robot")
        for robot_id in self.robots:
            check_robot_id(robot_id)
        names = self.all()
        for name in names:
            check_user_name(name)
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise ValueError(f"each user has one role, but {', '.join(repeated)} has more")

    def all(self) -> list[str]:
        """Every user name, the map node's first."""
        return [self.map_node, *self.robots, *self.operators, *self.viewers]


def check_user_name(name: str) -> str:
    """Return ``name`` if it can be a Zenoh user of a credentials file (letters, digits,
    ``. _ -``: no ``:``, which splits user from password, and no space), else raise."""
    if not _USER_NAME.fullmatch(name):
        raise ValueError(
            f"user name must be letters, digits, '.', '_' or '-' (a robot id is its user "
            f"name), got {name!r}"
        )
    return name


def _rule(rule_id: str, messages: list[str], key_exprs: list[str]) -> dict:
    return {
        "id": rule_id,
        "permission": "allow",
        "flows": ["ingress"],
        "messages": messages,
        "key_exprs": key_exprs,
    }


def site_access_control(map_ids: Sequence[str], users: SiteUsers) -> dict:
    """The router's ``access_control`` section for site maps ``map_ids`` and ``users``: default
    deny; each user's allowed ingress by role (module docstring); egress routes ``toploc/**``
    to anyone logged in (what reached the router passed its ingress rules)."""
    if not map_ids:
        raise ValueError("a site needs at least one map id")
    site_keys = [f"{ROOT}/map/{check_map_id(m)}/**" for m in map_ids]
    rules = [_rule("serve the site maps", SERVE, site_keys)]
    subjects = [{"id": "map node", "usernames": [users.map_node]}]
    policies = [{"id": "the map node", "rules": ["serve the site maps"], "subjects": ["map node"]}]
    for robot_id in users.robots:
        own = f"{ROOT}/{robot_id}/**"
        rules += [
            _rule(f"{robot_id} serves its keys", SERVE, [own]),
            _rule(f"{robot_id} uses its keys and the site maps", USE, [own, *site_keys]),
        ]
        subjects.append({"id": f"robot {robot_id}", "usernames": [robot_id]})
        policies.append(
            {
                "id": f"robot {robot_id}",
                "rules": [
                    f"{robot_id} serves its keys",
                    f"{robot_id} uses its keys and the site maps",
                ],
                "subjects": [f"robot {robot_id}"],
            }
        )
    if users.operators:
        rules.append(_rule("operate", USE, [f"{ROOT}/**"]))
        subjects.append({"id": "operators", "usernames": list(users.operators)})
        policies.append({"id": "operators", "rules": ["operate"], "subjects": ["operators"]})
    if users.viewers:
        reads = [f"{ROOT}/*/{suffix}" for suffix in READ_SUFFIXES]
        reads += [site_key(m, s) for m in map_ids for s in (SITE_VERSION, *READ_SUFFIXES[2:])]
        rules += [_rule("watch", SUBSCRIBE, [f"{ROOT}/**"]), _rule("read", ["query"], reads)]
        subjects.append({"id": "viewers", "usernames": list(users.viewers)})
        policies.append({"id": "viewers", "rules": ["watch", "read"], "subjects": ["viewers"]})
    rules.append(
        {
            "id": "route",
            "permission": "allow",
            "flows": ["egress"],
            "messages": sorted(set(SERVE + USE)),
            "key_exprs": [f"{ROOT}/**"],
        }
    )
    subjects.append({"id": "anyone logged in"})
    policies.append({"id": "routing", "rules": ["route"], "subjects": ["anyone logged in"]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def router_file(listen: Sequence[str], credentials_path: str, access_control: dict) -> dict:
    """The site router's Zenoh file: router mode on ``listen``, users checked against the
    credentials file at ``credentials_path`` (where the router reads it), ``access_control``."""
    return {
        "mode": "router",
        "listen": {"endpoints": list(listen)},
        "transport": {"auth": {"usrpwd": {"dictionary_file": credentials_path}}},
        "access_control": access_control,
    }


def client_file(router_endpoint: str, user: str, password: str) -> dict:
    """A user's Zenoh file: a client of the site router logging in as ``user``."""
    return {
        "mode": "client",
        "connect": {"endpoints": [router_endpoint]},
        "transport": {"auth": {"usrpwd": {"user": user, "password": password}}},
    }


def format_credentials(passwords: dict[str, str]) -> str:
    """The router's credentials file: a ``user:password`` line per user."""
    return "".join(f"{user}:{password}\n" for user, password in passwords.items())


def parse_credentials(text: str, source: str) -> dict[str, str]:
    """The users and passwords of a credentials file's ``text`` (``source`` names it in an
    error); blank lines are skipped, a line without ``:`` is an error naming its number."""
    passwords: dict[str, str] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        user, sep, password = line.partition(":")
        if not sep or not user or not password:
            raise ValueError(f"{source}: line {number} is not 'user:password'")
        passwords[user] = password
    return passwords

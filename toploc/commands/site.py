"""``toploc site access``: the Zenoh files of a site (docs/security.md, "A site"): the router's
file with one user and rules per robot (:mod:`toploc.bus.access_control`), its credentials file,
and a client file per user.

Run again in the same folder to add or drop a robot: every user already in its credentials file
is named again (and keeps its password: its client file is written again, the same) or dropped
with ``--drop``; new users get new passwords.
"""

from __future__ import annotations

import json
import os
import secrets
import tempfile
from pathlib import Path

import click

from toploc.bus.access_control import (
    SiteUsers,
    client_file,
    format_credentials,
    parse_credentials,
    router_file,
    site_access_control,
)

CREDENTIALS = "site-credentials.txt"
ROUTER = "router.json5"


@click.group("site")
def site_group() -> None:
    """Set up a site: one shared map, many robots, one router (docs/site.md)."""


def listen_endpoint(router_endpoint: str) -> str:
    """Where the router listens for clients that connect to ``router_endpoint``: the same
    protocol and port on every interface (``tcp/router.local:7447`` -> ``tcp/0.0.0.0:7447``)."""
    protocol, sep, address = router_endpoint.partition("/")
    host, colon, port = address.rpartition(":")
    if not sep or not colon or not host or not port.isdigit():
        raise click.BadParameter(
            f"expected PROTOCOL/HOST:PORT like tcp/site-router.local:7447, got {router_endpoint!r}",
            param_hint="'--router'",
        )
    return f"{protocol}/0.0.0.0:{port}"


def write_private(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` readable by its owner only (it holds passwords), replacing it
    in one step: a reader sees the old file or the new one, never half of one."""
    with tempfile.NamedTemporaryFile(
        "w", encoding="utf-8", dir=path.parent, prefix=f".{path.name}.", delete=False
    ) as out:
        out.write(text)
    os.chmod(out.name, 0o600)
    os.replace(out.name, path)


def json5_file(comment: str, content: dict) -> str:
    """A JSON5 file's text: a ``//`` comment line, then ``content`` as indented JSON."""
    return f"// {comment}\n{json.dumps(content, indent=2)}\n"


@site_group.command("access")
@click.option(
    "--map-id", "map_ids", multiple=True, required=True, help="A site map's id (repeat for more)."
)
@click.option(
    "--robot",
    "robots",
    multiple=True,
    required=True,
    help="A robot id: its user name, which may serve toploc/ROBOT_ID/** only (repeat).",
)
@click.option(
    "--router",
    "router_endpoint",
    required=True,
    help="Where clients reach the site router, e.g. tcp/site-router.local:7447.",
)
@click.option(
    "--listen",
    multiple=True,
    help="The router's own endpoint(s) (default: the --router protocol and port on 0.0.0.0).",
)
@click.option("--map-node-user", default="map-node", show_default=True, help="The map node's user.")
@click.option(
    "--operator",
    "operators",
    multiple=True,
    help="A user who may ask any robot or map anything (belief, localize, drive); serves nothing.",
)
@click.option(
    "--viewer",
    "viewers",
    multiple=True,
    help="A user who may watch everything and query what only reads (beliefs, odometry, maps).",
)
@click.option(
    "--drop",
    multiple=True,
    help="A user of an earlier run to leave out (repeat); every other one must be named again.",
)
@click.option(
    "--credentials-at",
    default=None,
    help=f"Where the router will read the credentials file (default: OUT/{CREDENTIALS}, absolute).",
)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("site-access"),
    show_default=True,
    help="The folder the files go to.",
)
def access(
    map_ids: tuple[str, ...],
    robots: tuple[str, ...],
    router_endpoint: str,
    listen: tuple[str, ...],
    map_node_user: str,
    operators: tuple[str, ...],
    viewers: tuple[str, ...],
    drop: tuple[str, ...],
    credentials_at: str | None,
    out_dir: Path,
) -> None:
    """Write a site's Zenoh files to OUT: router.json5 (one user and rules per robot),
    site-credentials.txt (a password per user) and USER.json5 for each user (the map node's,
    each robot's: pass it as --zenoh-config). Run again in OUT to add robots (name the earlier
    users again: they keep their passwords) or --drop some."""
    try:
        users = SiteUsers(tuple(robots), map_node_user, tuple(operators), tuple(viewers))
        access_control = site_access_control(map_ids, users)
    except ValueError as error:
        raise click.UsageError(str(error)) from None
    listen = listen or (listen_endpoint(router_endpoint),)
    out_dir.mkdir(parents=True, exist_ok=True)
    credentials = out_dir / CREDENTIALS
    old: dict[str, str] = {}
    if credentials.exists():
        try:
            old = parse_credentials(credentials.read_text(encoding="utf-8"), str(credentials))
        except (OSError, UnicodeDecodeError, ValueError) as error:
            raise click.ClickException(
                f"{credentials}: cannot keep its passwords: {error}"
            ) from None
    forgotten = [u for u in old if u not in users.all() and u not in drop]
    if forgotten:
        raise click.UsageError(
            f"{', '.join(forgotten)} in {credentials} but not named: name them again "
            f"(--robot, --operator, --viewer, --map-node-user) or --drop them"
        )
    passwords = {user: old.get(user) or secrets.token_urlsafe(18) for user in users.all()}
    write_private(credentials, format_credentials(passwords))
    where = credentials_at or str(credentials.resolve())
    router = router_file(listen, where, access_control)
    write_private(
        out_dir / ROUTER, json5_file(f"{ROUTER}: the site's router: zenohd -c {ROUTER}", router)
    )
    for user, password in passwords.items():
        comment = f"{user}.json5: pass it as --zenoh-config"
        write_private(
            out_dir / f"{user}.json5",
            json5_file(comment, client_file(router_endpoint, user, password)),
        )
    new = [u for u in passwords if u not in old]
    click.echo(f"wrote {ROUTER}, {CREDENTIALS} and {len(passwords)} user files to {out_dir}")
    click.echo(
        f"users: {', '.join(passwords)}" + (f" (new: {', '.join(new)})" if old and new else "")
    )
    dropped = [u for u in drop if u in old]
    if dropped:
        click.echo(f"dropped: {', '.join(dropped)} (their .json5 files are left)")
    click.echo(f"the router reads its credentials at {where}; copy them there if that is elsewhere")

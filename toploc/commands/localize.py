"""``toploc localize``: the one-shot belief over rooms for one panorama.

Bad input (a missing or corrupt image, a missing or damaged map) is a one-line ``Error: ...``
naming the file, and exit status 1.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import click

from localizer.belief import RoomBelief
from localizer.cameras import parse_camera
from localizer.localizer import Localizer, LocalizerConfig, Observation
from localizer.panorama_io import PanoramaError, read_panorama
from mapdb.errors import MapDatabaseError
from toploc.commands.belief_text import format_belief
from toploc.commands.options import camera_option, db_option
from toploc.maps import load_map


@contextmanager
def localizer_errors() -> Iterator[None]:
    """Bad images, bad maps and bad settings become ``Error: <message>``, exit status 1."""
    try:
        yield
    except (MapDatabaseError, PanoramaError, ValueError, KeyError) as error:
        raise click.ClickException(str(error)) from error


def load_localizer(
    db_path: Path, detector: str, index: bool | None, camera: str = "auto"
) -> Localizer:
    """The localizer on the map at ``db_path`` with the ``detector`` fingerprints, reading
    queries through the ``camera`` model (a ``--camera`` text)."""
    if not db_path.is_file():
        raise click.ClickException(f"map database {db_path} does not exist")
    loaded = load_map(db_path, detector, use_index=index)
    return Localizer(loaded, LocalizerConfig(detector=detector, camera=parse_camera(camera)))


def describe(belief: RoomBelief, observation: Observation, top: int = 5) -> str:
    """A few lines for people: the belief (:func:`format_belief`, the ``top`` rooms), the best
    places and the timings."""
    lines = [format_belief(belief.to_json(), top)]
    lines.append("best places (room, place id, inliers / matches, share of the horizon):")
    lines += [
        f"  {e.room:14s} {e.place_id:5d} {e.inliers:5d} / {e.matches:<5d} {e.coverage:4.0%}"
        for e in observation.evidence.places[:top]
    ]
    timing = ", ".join(f"{k} {v:.0f} ms" for k, v in observation.timing_ms.items())
    lines.append(f"time: {timing}")
    return "\n".join(lines)


map_db_option = db_option("The map database (SQLite), built by toploc map build.")
detector_option = click.option(
    "--detector",
    default="sift",
    show_default=True,
    help="The fingerprints to match: a detector the map holds (sift; mser if the map was "
    "built with it).",
)
index_option = click.option(
    "--index/--brute-force",
    default=None,
    help="Shortlist places with the descriptor index [default: when the map has 32+ places].",
)


@click.command("localize")
@click.argument("image", type=click.Path(dir_okay=False, path_type=Path))
@map_db_option
@detector_option
@index_option
@camera_option
@click.option("--json", "as_json", is_flag=True, help="Print the belief as JSON.")
def localize(
    image: Path, db_path: Path, detector: str, index: bool | None, camera: str, as_json: bool
) -> None:
    """Which room is the panorama IMAGE from? The one-shot belief over the map's rooms."""
    with localizer_errors():
        panorama = read_panorama(image)
        localizer = load_localizer(db_path, detector, index, camera)
        belief, observation = localizer.localize_once(panorama, str(image))
    if as_json:
        report = belief.to_json() | {"timing_ms": dict(observation.timing_ms)}
        click.echo(json.dumps(report, indent=2))
    else:
        click.echo(describe(belief, observation))

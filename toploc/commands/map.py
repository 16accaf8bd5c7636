"""``toploc map``: build, extend, connect, inspect and export the map database.

Every :class:`~mapdb.errors.MapDatabaseError` becomes a one-line ``Error: ...`` and exit status
1. ``map build`` exits 1 if any image failed (the others are imported) and 130 if interrupted
by Ctrl-C or ``SIGTERM`` (the map stays consistent; re-running completes it). Also runnable as
``python -m toploc.commands.map``.

Feature extraction is :func:`toploc.extraction.extract_panorama` (``localizer.panorama_io`` +
``localizer.features``), bound to the chosen presets by ``resolve_extractor``.
"""

from __future__ import annotations

import json
import math
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import click
from tqdm import tqdm

from mapdb.build import BuildReport, Outcome, Status, build_map
from mapdb.database import MapDatabase
from mapdb.dataset import (
    EDGES_NAME,
    ManifestEntry,
    check_edge_rooms,
    read_dataset,
    read_edge_rows,
)
from mapdb.errors import MapDatabaseError
from mapdb.graph import connect_known_rooms, export_graphml
from mapdb.records import check_name
from toploc.commands.map_text import (
    describe_likelihood,
    explain_likelihood,
    format_info,
    lookalike_lines,
)
from toploc.commands.options import camera_option, db_option
from toploc.commands.record import record_command
from toploc.extraction import map_overrides, resolve_extractor
from toploc.map_index import refresh_index_files

DEFAULT_DETECTORS = ("sift",)
"""What ``map build`` and ``map add`` extract unless told: what ``localize`` reads by default."""
EXIT_FAILED = 1
EXIT_INTERRUPTED = 130


def parse_detectors(text: str | tuple[str, ...]) -> tuple[str, ...]:
    """``"sift,mser"`` or ``("sift", "mser")`` (a repeated ``--detector``, each may list
    several) -> ``("sift", "mser")``; each an extraction preset, each detector once."""
    from localizer.features import PRESETS, params_from_preset

    texts = (text,) if isinstance(text, str) else text
    presets = tuple(name.strip() for part in texts for name in part.split(",") if name.strip())
    if not presets:
        raise click.BadParameter("give at least one detector, e.g. sift,mser")
    unknown = [name for name in presets if name not in PRESETS]
    if unknown:
        raise click.BadParameter(f"unknown detector {unknown[0]!r}; known: {sorted(PRESETS)}")
    detectors = [params_from_preset(name).detector for name in presets]
    if len(set(detectors)) != len(detectors):
        raise click.BadParameter(f"each detector may appear once, got {', '.join(presets)}")
    return presets


@contextmanager
def _map_errors() -> Iterator[None]:
    """Turn a MapDatabaseError into click's ``Error: <message>`` with exit status 1."""
    try:
        yield
    except MapDatabaseError as error:
        raise click.ClickException(str(error)) from error


@contextmanager
def _removed_if_left_empty(db_path: Path) -> Iterator[None]:
    """Within the block, a map file that did not exist before is deleted again if the block
    fails and the map was left without a place (a refused first ``map add`` leaves no empty
    map behind); an existing file is never touched."""
    existed = db_path.exists()
    try:
        yield
    except BaseException:
        if not existed and db_path.exists() and _has_no_places(db_path):
            for path in (db_path, *(Path(f"{db_path}{tail}") for tail in ("-wal", "-shm"))):
                path.unlink(missing_ok=True)
        raise


def _has_no_places(db_path: Path) -> bool:
    """Whether the map at ``db_path`` opens and holds no place (False if it cannot be read)."""
    try:
        with MapDatabase.open(db_path, readonly=True) as map_db:
            return map_db.info().n_places == 0
    except MapDatabaseError:
        return False


def _raise_interrupt(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signal.Signals(signum).name}")


@contextmanager
def _sigterm_as_interrupt() -> Iterator[None]:
    """Within the block, ``SIGTERM`` stops the command as Ctrl-C does (a KeyboardInterrupt: the
    build ends cleanly, its workers stopped, exit 130). Left alone if a handler is set already
    (e.g. by the CLI) or outside the main thread."""
    in_main = threading.current_thread() is threading.main_thread()
    if not in_main or signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL:
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _log_outcome(outcome: Outcome, verbose: bool) -> None:
    """Failures and warnings always, one line each, under the progress bar; the rest with
    ``--verbose``."""
    if outcome.status is Status.FAILED or outcome.warning or verbose:
        tqdm.write(outcome.describe(), file=sys.stderr)


def _summarize(report: BuildReport, db_path: Path, elapsed_s: float, verbose: bool) -> None:
    """The result first: what was added, skipped and failed, how long it took, and what the
    map holds now."""
    with MapDatabase.open(db_path, create=False, readonly=True) as map_db:
        rooms = map_db.rooms()
    places = sum(room.n_places for room in rooms)
    click.echo(
        f"{db_path}: {report.summary()} in {elapsed_s:.1f} s; the map holds {places} places "
        f"in {len(rooms)} rooms"
    )
    skipped = report.count(Status.SKIPPED)
    if skipped and not verbose:
        click.echo(f"skipped {skipped} image(s) already in the map (-v lists them)")


def _finish(report: BuildReport) -> None:
    """Exit 130 if interrupted, 1 if any image failed."""
    if report.interrupted:
        click.echo("interrupted: the map is consistent; run the same command again to finish")
        raise SystemExit(EXIT_INTERRUPTED)
    failed = [o.image for o in report.outcomes if o.status is Status.FAILED]
    if failed:
        raise click.ClickException(f"{len(failed)} image(s) failed: {', '.join(failed)}")


map_db_option = db_option("The map database file (SQLite).")
calibrate_option = click.option(
    "--calibrate/--no-calibrate",
    default=True,
    show_default=True,
    help="Fit the likelihood on the map's own places afterwards (see `toploc map calibrate`).",
)
read_width_option = click.option(
    "--read-width",
    "read_width_px",
    type=click.IntRange(min=8),
    default=None,
    help=(
        "Shrink panoramas wider than this many pixels before detection [default: the "
        "camera's: 1024 for a sphere, none for a cylinder]. The map keeps it: its queries and "
        "later places are read the same way (2048: a 2048 x 1024 camera at full size, slower "
        "and more detail)."
    ),
)
detector_option = click.option(
    "--detector",
    "detectors",
    multiple=True,
    help="An extraction preset to store (repeatable, or comma-separated: --detector sift "
    "--detector mser; sift, mser, sift-lower, mser-band20, ...) [default: the detectors the "
    "map holds; sift for a new map, what toploc localize reads unless told otherwise].",
)


def _presets_for(map_db: MapDatabase, given: tuple[str, ...]) -> tuple[str, ...]:
    """``given`` (already checked by :func:`parse_detectors`), else the detectors the map
    holds (sift first), else :data:`DEFAULT_DETECTORS`."""
    held = sorted(map_db.fingerprint_counts(), key=lambda name: (name != "sift", name))
    return given or tuple(held) or DEFAULT_DETECTORS


@click.group("map")
def map_group() -> None:
    """Build and inspect the map database: rooms, their graph, places and fingerprints."""


@map_group.command("build")
@click.argument("dataset", type=click.Path(file_okay=False, path_type=Path))
@map_db_option
@detector_option
@click.option(
    "--workers",
    type=click.IntRange(min=0),
    default=os.cpu_count() or 1,
    show_default=True,
    help="Extraction processes (0 or 1: in this process).",
)
@camera_option
@read_width_option
@calibrate_option
@click.option(
    "--allow-outside",
    is_flag=True,
    help="Import manifest images that lie outside DATASET (absolute paths, '..', symlinks).",
)
@click.option(
    "--create-rooms",
    is_flag=True,
    help="Create the rooms edges.csv names that have no panorama (an error otherwise).",
)
@click.option("--progress/--no-progress", default=True, help="Show a progress bar.")
@click.option(
    "-v",
    "--verbose",
    is_flag=True,
    help="List every image, not only failures, and print the likelihood's formula.",
)
def build_command(
    dataset: Path,
    db_path: Path,
    detectors: tuple[str, ...],
    workers: int,
    camera: str,
    read_width_px: int | None,
    calibrate: bool,
    allow_outside: bool,
    create_rooms: bool,
    progress: bool,
    verbose: bool,
) -> None:
    """Import the panoramas of DATASET into the map: a folder with manifest.csv, or without
    one, a folder with one sub-folder of panoramas per room (named after the room; no poses).

    Images already in the map (same SHA-256) are skipped; re-run after an interruption to finish.
    An optional edges.csv (room_a,room_b) beside the manifest adds the room graph's edges.
    Only regular files inside DATASET are read (see --allow-outside); a room of edges.csv must
    be in the manifest or the map (see --create-rooms).
    """
    given = parse_detectors(detectors) if detectors else ()
    started_s = time.monotonic()
    with _sigterm_as_interrupt(), _map_errors():
        entries = read_dataset(dataset, allow_outside=allow_outside)
        edge_rows = read_edge_rows(dataset)
        edges = [(a, b) for a, b, _ in edge_rows]
        with MapDatabase.open(db_path) as map_db:
            if not create_rooms:
                known = {entry.room for entry in entries} | {r.name for r in map_db.rooms()}
                check_edge_rooms(dataset, edge_rows, known)
            presets = _presets_for(map_db, given)
            report = build_map(
                map_db,
                entries,
                resolve_extractor(presets, camera, _overrides(map_db, read_width_px)),
                workers=workers,
                progress=progress,
                on_outcome=lambda outcome: _log_outcome(outcome, verbose),
            )
            added = 0
            if not report.interrupted:
                for room in {room for edge in edges for room in edge} if create_rooms else ():
                    map_db.add_room(room)
                added = connect_known_rooms(map_db, edges)
        _summarize(report, db_path, time.monotonic() - started_s, verbose)
        if not report.interrupted and added:
            click.echo(f"connected {added} pair(s) of rooms from {EDGES_NAME}")
        if calibrate and not report.interrupted and report.count(Status.ADDED):
            _calibrate(db_path, presets, progress, verbose)
    _finish(report)


@map_group.command("add")
@click.argument("image", type=click.Path(dir_okay=False, path_type=Path))
@map_db_option
@click.option("--room", required=True, help="The room the panorama was taken in.")
@click.option("--x-m", type=float, default=None, help="x in the room's frame, metres.")
@click.option("--y-m", type=float, default=None, help="y in the room's frame, metres.")
@click.option("--heading-deg", type=float, default=None, help="Heading in the room, degrees CCW.")
@detector_option
@camera_option
@read_width_option
@calibrate_option
def add_command(
    image: Path,
    db_path: Path,
    room: str,
    x_m: float | None,
    y_m: float | None,
    heading_deg: float | None,
    detectors: tuple[str, ...],
    camera: str,
    read_width_px: int | None,
    calibrate: bool,
) -> None:
    """Add one panorama IMAGE as a place of ROOM (the room is created if new)."""
    if (x_m is None) != (y_m is None):
        raise click.UsageError("give both --x-m and --y-m, or neither")
    for hint, value in (("--x-m", x_m), ("--y-m", y_m), ("--heading-deg", heading_deg)):
        if value is not None and not math.isfinite(value):
            raise click.ClickException(f"{hint} must be a finite number, got {value}")
    try:
        check_name(room.strip())
    except ValueError as error:
        raise click.ClickException(f"--room: {error}") from None
    given = parse_detectors(detectors) if detectors else ()
    entry = ManifestEntry(image.name, image, room.strip(), x_m, y_m, heading_deg, line=0)
    with _map_errors(), _removed_if_left_empty(db_path):
        with MapDatabase.open(db_path) as map_db:
            presets = _presets_for(map_db, given)
            extractor = resolve_extractor(presets, camera, _overrides(map_db, read_width_px))
            report = build_map(map_db, [entry], extractor, workers=0, progress=False)
        (outcome,) = report.outcomes or [Outcome(image.name, Status.FAILED, message="interrupted")]
        if outcome.status is Status.FAILED:
            named = outcome.message.startswith((f"{image}:", f"{image.name}:"))
            raise click.ClickException(outcome.message if named else f"{image}: {outcome.message}")
    click.echo(outcome.describe())
    if outcome.status is Status.ADDED:
        with _map_errors():
            refresh_index_files(db_path)  # a big map's compact index: the place encoded
    if calibrate and outcome.status is Status.ADDED:
        with _map_errors():
            _calibrate(db_path, presets, progress=False)


@map_group.command("calibrate")
@map_db_option
@click.option(
    "--detector",
    "detectors",
    default=None,
    help="Comma-separated detectors to calibrate [default: every detector the map holds].",
)
@click.option("--progress/--no-progress", default=True, help="Show a progress bar.")
def calibrate_command(db_path: Path, detectors: str | None, progress: bool) -> None:
    """Fit the likelihood of each detector's evidence on the map's own places and store it.

    Each of up to 60 places, spread over the rooms, is localized against the map without it;
    the inliers of its own room and of the other rooms give the model (docs/localization.md).
    `map build` and `map add` do this themselves unless --no-calibrate is given.
    """
    with _map_errors():
        _calibrate(db_path, parse_detectors(detectors or _held_detectors(db_path)), progress)


def _held_detectors(db_path: Path) -> str:
    """The detectors the map holds fingerprints of, comma-separated; a click error for a
    missing map or one without fingerprints."""
    if not db_path.is_file():
        raise click.ClickException(f"map database {db_path} does not exist")
    with MapDatabase.open(db_path, create=False, readonly=True) as map_db:
        held = sorted(map_db.info().fingerprints_per_detector)
    if not held:
        raise click.ClickException(f"{db_path} has no fingerprints to calibrate on")
    return ",".join(held)


def _overrides(map_db: MapDatabase, read_width_px: int | None) -> dict[str, Any]:
    """The extraction settings a new place takes (:func:`toploc.extraction.map_overrides`),
    with ``--read-width``: a new map takes it, a map whose places were read otherwise refuses
    it (one map reads all its places, and its queries, one way)."""
    from localizer.features import ExtractionParams

    overrides = map_overrides(map_db)
    stored = map_db.stored_params()
    if read_width_px is None:
        return overrides
    if stored is not None:
        width = ExtractionParams.from_record(stored).max_width_px
        if width != read_width_px:
            how = f"at up to {width} px wide" if width else "at their full width"
            raise click.UsageError(
                f"--read-width {read_width_px}: the map's places were read {how}, and a map "
                f"reads all its places one way; leave --read-width out to follow the map"
            )
    return {**overrides, "max_width_px": read_width_px}


def _calibrate(
    db_path: Path,
    presets: tuple[str, ...],
    progress: bool,
    formula: bool = False,
    declare: tuple[str, str] | None = None,
) -> None:
    """Calibrate and store the likelihood of every preset's detector; one line each in plain
    words (and its formula with ``formula``), with the time it took; ``declare``: a pair of
    look-alike rooms the user names (:func:`toploc.maps.calibrate_map`)."""
    from localizer.features import params_from_preset
    from toploc.maps import calibrate_map

    for preset in presets:
        detector = params_from_preset(preset).detector
        started_s = time.monotonic()
        try:
            model = calibrate_map(db_path, detector, progress, declare=declare)
        except ValueError as error:
            raise click.ClickException(str(error)) from error
        took = f" ({time.monotonic() - started_s:.1f} s)"
        if declare is not None:
            click.echo(f"declared look-alikes: {declare[0]} and {declare[1]}")
        click.echo(f"{explain_likelihood(detector, model)}{took}")
        with MapDatabase.open(db_path, readonly=True) as map_db:
            places, edges = map_db.places(), map_db.edges()
        for line in lookalike_lines(model, places, edges):
            click.echo(line)
        if formula:
            click.echo(f"  {detector} likelihood: {describe_likelihood(model)}")


@map_group.command("lookalike")
@click.argument("room_a")
@click.argument("room_b")
@map_db_option
@click.option("--progress/--no-progress", default=True, help="Show a progress bar.")
def lookalike_command(room_a: str, room_b: str, db_path: Path, progress: bool) -> None:
    """Declare that ROOM_A and ROOM_B look alike (two identical offices), and calibrate again.

    The calibration finds look-alike rooms only where their places show it; twins whose places
    were recorded at different spots of their identical frames can look like two rooms. A
    declared pair is weighed as equally likely wherever the frame cannot tell them apart, and
    is kept by every later calibration (docs/localization.md).
    """
    with _map_errors():
        presets = parse_detectors(_held_detectors(db_path))
        _calibrate(db_path, presets, progress, declare=(room_a, room_b))


@map_group.command("connect")
@click.argument("room_a")
@click.argument("room_b")
@map_db_option
def connect_command(room_a: str, room_b: str, db_path: Path) -> None:
    """Record that the robot can drive between ROOM_A and ROOM_B (an undirected edge)."""
    if room_a == room_b:
        raise click.BadParameter(f"cannot connect room {room_a!r} to itself")
    with _map_errors(), MapDatabase.open(db_path, create=False) as map_db:
        added = map_db.connect_rooms(room_a, room_b)
    state = "connected" if added else "already connected:"
    click.echo(f"{state} {room_a} <-> {room_b}")


@map_group.command("info")
@map_db_option
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of text.")
def info_command(db_path: Path, as_json: bool) -> None:
    """Rooms, places per room, fingerprints per detector, edges and file size; the map's id and
    version (what a site's replicas follow)."""
    with _map_errors(), MapDatabase.open(db_path, readonly=True) as map_db:
        info = map_db.info()
        places = map_db.places()
        identity = {"map_id": map_db.map_id(), "map_version": map_db.map_version()}
    if as_json:
        click.echo(json.dumps({**info.to_json(), **identity}, indent=2))
        return
    click.echo(format_info(info, places))
    click.echo(f"map id {identity['map_id']}, version {identity['map_version']}")


@map_group.command("export")
@map_db_option
@click.option(
    "--graphml",
    "graphml_path",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="Output GraphML file.",
)
def export_command(db_path: Path, graphml_path: Path) -> None:
    """Export the room graph (rooms as nodes, with their place counts) as GraphML."""
    with _map_errors(), MapDatabase.open(db_path, readonly=True) as map_db:
        graph = export_graphml(map_db, graphml_path)
    click.echo(
        f"wrote {graphml_path}: {graph.number_of_nodes()} rooms, {graph.number_of_edges()} edges"
    )


map_group.add_command(record_command)

if __name__ == "__main__":
    map_group()

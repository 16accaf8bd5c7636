"""``toploc eval homing``: ALV homing between every pair of places of a dataset (thesis 5.6-5.7).

Bad input (a missing folder or manifest, a malformed manifest, an unreadable image, no room with
two places) is a one-line ``Error: ...`` naming the file, and exit status 1.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import click
import numpy as np

from localizer.features import DEFAULT_PARAMS, DETECTORS
from localizer.panorama_io import PanoramaError
from mapdb.dataset import ManifestEntry
from mapdb.errors import MapDatabaseError
from toploc.commands.options import camera_option
from toploc.evaluation.homing import (
    BEST_METHOD,
    METHODS,
    EvaluationError,
    FeatureSettings,
    HomingRun,
    PairCache,
    evaluate_homing,
    extract_fingerprints,
    headings_rad,
    load_places,
    positions_m,
)


@contextmanager
def evaluation_errors() -> Iterator[None]:
    """Turn bad-input errors into click's one-line ``Error: <message>`` with exit status 1."""
    try:
        yield
    except (MapDatabaseError, PanoramaError, EvaluationError) as error:
        raise click.ClickException(str(error)) from error


def _finite(_ctx: click.Context, param: click.Parameter, value: float) -> float:
    """``value`` if it is a finite number (click's ranges let NaN through)."""
    if not math.isfinite(value):
        raise click.BadParameter(f"must be a finite number, got {value}", param=param)
    return value


def extraction_options(function: click.decorators.FC) -> click.decorators.FC:
    """The shared ``DATASET --detector --camera --band-deg --rows --clahe-clip --workers
    --progress`` options (the band and the halves are elevations of each image's camera
    model)."""
    decorators = [
        click.argument("dataset", type=click.Path(path_type=Path)),
        click.option(
            "--detector",
            type=click.Choice(DETECTORS),
            default="sift",
            show_default=True,
            help="Feature detector (sift = DoG keypoints).",
        ),
        camera_option,
        click.option(
            "--band-deg",
            type=click.FloatRange(0, 90, max_open=True),
            default=None,
            help="Keep features within ± this many degrees of elevation of the horizon.",
        ),
        click.option(
            "--rows",
            type=click.Choice(("all", "lower", "upper")),
            default="all",
            show_default=True,
            help="Keep features of all rows or those below (lower) or above (upper) the horizon.",
        ),
        click.option(
            "--clahe-clip",
            type=click.FloatRange(min=0),
            default=DEFAULT_PARAMS.clahe_clip_limit,
            show_default=True,
            callback=_finite,
            help=(
                "Contrast equalisation's clip limit (0: the images as given; the 1,000-keypoint "
                "cap still applies)."
            ),
        ),
        click.option(
            "--workers",
            type=click.IntRange(min=0),
            default=os.cpu_count() or 1,
            show_default=True,
            help="Extraction processes (0 or 1: in this process).",
        ),
        click.option("--progress/--no-progress", default=True, help="Show progress bars."),
    ]
    for decorator in reversed(decorators):
        function = decorator(function)
    return function


def load_and_extract(
    dataset: Path, settings: FeatureSettings, workers: int, progress: bool
) -> tuple[tuple[ManifestEntry, ...], list, float]:
    """The places of ``dataset``, their fingerprints, and the extraction time in seconds."""
    places = load_places(dataset)
    start = time.perf_counter()
    fingerprints = extract_fingerprints([p.path for p in places], settings, workers, progress)
    return places, fingerprints, time.perf_counter() - start


def _plot(run: HomingRun, path: Path, title: str) -> None:
    from homing.thesis.eval_plots import plot_home_vectors

    home_image = run.stats.best_home
    home = next(k for k, p in enumerate(run.places) if p.image == home_image)
    room = run.places[home].room
    members = [k for k, p in enumerate(run.places) if p.room == room]
    headings = headings_rad(run.places)
    directions = np.full(len(members), np.nan)
    for row, k in enumerate(members):
        chosen = np.flatnonzero((run.here == k) & (run.home == home))
        if len(chosen) and not np.isnan(headings[k]):
            directions[row] = run.home_direction_rad[chosen[0]] + headings[k]
    plot_home_vectors(
        positions_m(run.places)[members],
        members.index(home),
        directions,
        path,
        title=f"{title}: home {home_image} ({room})",
    )


@click.command("homing")
@extraction_options
@click.option(
    "--method",
    "methods",
    type=click.Choice(METHODS),
    multiple=True,
    default=("thesis",),
    show_default=True,
    help=(
        f"thesis: ALV of all bearings, headings known; best: {BEST_METHOD}. Repeat to "
        "evaluate several methods on the same features and matches."
    ),
)
@click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Write the statistics as JSON (a list when several methods are given).",
)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Draw the home vectors to the best home (PNG; of the first method).",
)
def homing_command(
    dataset: Path,
    detector: str,
    camera: str,
    band_deg: float | None,
    rows: str,
    clahe_clip: float,
    workers: int,
    progress: bool,
    methods: tuple[str, ...],
    json_path: Path | None,
    plot_path: Path | None,
) -> None:
    """Home from every place of DATASET to every other place of its room; print the errors.

    Prints, per method, mean, median and standard deviation of the angular error (eq. 5.5,
    degrees), the score (eq. 5.6), the best home, n, and the shares of errors under 90° and 10°.
    """
    settings = FeatureSettings(detector, camera, band_deg, rows, clahe_clip)
    records = []
    with evaluation_errors():
        places, fingerprints, extract_s = load_and_extract(dataset, settings, workers, progress)
        cameras = sorted({str(f.params.get("camera", "cylinder")) for f in fingerprints})
        filters = f"rows={rows}" + ("" if band_deg is None else f" band={band_deg:g}deg")
        filters += f" clahe={clahe_clip:g}"
        click.echo(f"{dataset}: {detector} {filters}, camera {'/'.join(cameras)}")
        click.echo(f"  time: extraction {extract_s:.1f} s")
        cache = PairCache(fingerprints, progress)
        for k, method in enumerate(methods):
            start = time.perf_counter()
            run = evaluate_homing(places, fingerprints, method, progress, cache)
            pairs_s = time.perf_counter() - start
            record = _report(run, method, pairs_s)
            records.append({**record, "detector": detector, "camera": camera, "rows": rows,
                            "band_deg": band_deg, "clahe_clip": clahe_clip,
                            "dataset": str(dataset)})  # fmt: skip
            if plot_path is not None and k == 0:
                _plot(run, plot_path, f"{detector} {filters} {method}")
                click.echo(f"  wrote {plot_path}")
    if json_path is not None:
        payload = records[0] if len(records) == 1 else records
        json_path.write_text(json.dumps(payload, indent=2) + "\n")


def _report(run: HomingRun, method: str, pairs_s: float) -> dict:
    """Print one method's statistics; return them as a JSON-ready record."""
    stats = run.stats
    resolved = BEST_METHOD if method == "best" else method
    click.echo(f"  method {method} ({resolved})")
    click.echo(
        f"    mean {stats.mean_deg:.2f} deg, median {stats.median_deg:.2f} deg, "
        f"std {stats.std_deg:.2f} deg, score {stats.score:.4f}"
    )
    click.echo(
        f"    best home {stats.best_home}, n {stats.n} ({stats.n_pairs} pairs, "
        f"{stats.n_failed} failed), under 90 deg {100 * stats.under_90:.1f}%, "
        f"under 10 deg {100 * stats.under_10:.1f}%, time {pairs_s:.1f} s"
    )
    return stats.to_json(method=method, resolved_method=resolved)

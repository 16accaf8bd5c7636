"""``toploc eval localize``: single-shot localization of every panorama of a dataset against a
map (queries under other conditions than the map), or leave-one-out on the map's own places.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from toploc.commands.localize import (
    detector_option,
    index_option,
    load_localizer,
    localizer_errors,
    map_db_option,
)
from toploc.commands.options import camera_option
from toploc.evaluation.localization import (
    format_confusion,
    localize_dataset,
    localize_leave_one_out,
)
from toploc.evaluation.localization_report import (
    format_calibration,
    format_outcomes,
    format_per_room,
    format_timing,
)


@click.command("localize")
@click.argument("dataset", type=click.Path(file_okay=False, path_type=Path), required=False)
@map_db_option
@detector_option
@index_option
@camera_option
@click.option(
    "--leave-one-out",
    is_flag=True,
    help="Query the map's own places, each against the map without it (no DATASET).",
)
@click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write the scores to this JSON file (keys: see docs/cli.md).",
)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Plot calibration (stated probability against how often right) and the outcomes (PNG).",
)
@click.option("--progress/--no-progress", default=True, help="Show a progress bar.")
def localize_command(
    dataset: Path | None,
    db_path: Path,
    detector: str,
    index: bool | None,
    camera: str,
    leave_one_out: bool,
    json_path: Path | None,
    plot_path: Path | None,
    progress: bool,
) -> None:
    """Localize every panorama of DATASET against the map: a folder with manifest.csv, or one
    sub-folder of panoramas per room (named after the room).

    Prints the outcomes of the queries from rooms of the map, counted in five: right and
    localized, right but ambiguous, wrong and localized (confidently wrong), wrong and
    ambiguous, lost; their top-1 room accuracy (a lost answer is never right); then the
    queries from rooms the map lacks on a line of their own (right only when lost); per true
    room, the calibration of the stated probability, the confusion matrix and the time per
    query. --json writes them (keys: docs/cli.md).
    """
    if (dataset is None) == (not leave_one_out):
        raise click.UsageError("give a DATASET or --leave-one-out (not both)")
    with localizer_errors():
        localizer = load_localizer(db_path, detector, index, camera)
        if leave_one_out:
            run = localize_leave_one_out(localizer, progress)
        else:
            assert dataset is not None
            run = localize_dataset(localizer, dataset, progress)
    score = run.score
    sections = [format_outcomes(score), format_per_room(score)]
    sections += [format_calibration(score), format_confusion(score.confusion), format_timing(score)]
    click.echo("\n".join(section for section in sections if section))
    if json_path is not None:
        json_path.write_text(json.dumps(score.to_json(), indent=2) + "\n")
        click.echo(f"wrote {json_path}")
    if plot_path is not None:
        from toploc.evaluation.localization_plots import plot_localization  # matplotlib on demand

        name = "leave-one-out" if dataset is None else dataset.name
        plot_localization(score.calibration, score.outcomes, plot_path, title=name)
        click.echo(f"wrote {plot_path}")

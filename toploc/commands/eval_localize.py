"""``toploc eval localize``: single-shot localization of every panorama of a dataset against a
map (queries under other conditions than the map), or leave-one-out on the map's own places.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from toploc.commands.localize import (
    db_option,
    detector_option,
    index_option,
    load_localizer,
    localizer_errors,
)
from toploc.evaluation.localization import (
    format_confusion,
    localize_dataset,
    localize_leave_one_out,
)


@click.command("localize")
@click.argument("dataset", type=click.Path(file_okay=False, path_type=Path), required=False)
@db_option
@detector_option
@index_option
@click.option(
    "--leave-one-out",
    is_flag=True,
    help="Query the map's own places, each against the map without it (no DATASET).",
)
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--progress/--no-progress", default=True)
def localize_command(
    dataset: Path | None,
    db_path: Path,
    detector: str,
    index: bool | None,
    leave_one_out: bool,
    json_path: Path | None,
    progress: bool,
) -> None:
    """Localize every panorama of DATASET (a folder with manifest.csv) against the map.

    Prints top-1 room accuracy, the share marked ambiguous, the confusion matrix and the time
    per query; --json writes n, top1, ambiguous_rate, per_room, confusion, ms_median, ms_p95.
    """
    if (dataset is None) == (not leave_one_out):
        raise click.UsageError("give a DATASET or --leave-one-out (not both)")
    with localizer_errors():
        localizer = load_localizer(db_path, detector, index)
        if leave_one_out:
            run = localize_leave_one_out(localizer, progress)
        else:
            assert dataset is not None
            run = localize_dataset(localizer, dataset, progress)
    score = run.score
    click.echo(
        f"n {score.n}: top-1 room {score.top1:.1%}, ambiguous {score.ambiguous_rate:.1%}, "
        f"{score.ms_median:.0f} ms median / {score.ms_p95:.0f} ms p95 per query "
        f"({', '.join(f'{k} {v:.0f}' for k, v in score.stage_ms_median.items())} ms median)"
    )
    for room, row in score.per_room.items():
        click.echo(
            f"  {room:14s} n {row['n']:3.0f}  top-1 {row['top1']:6.1%}  "
            f"ambiguous {row['ambiguous_rate']:6.1%}"
        )
    click.echo(format_confusion(score.confusion))
    if json_path is not None:
        json_path.write_text(json.dumps(score.to_json(), indent=2) + "\n")
        click.echo(f"wrote {json_path}")

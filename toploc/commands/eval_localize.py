"""``toploc eval localize``: single-shot localization of every panorama of a dataset against a
map (queries under other conditions than the map), or leave-one-out on the map's own places.
"""

from __future__ import annotations

import json
from pathlib import Path

import click
from tqdm import tqdm

from localizer.localizer import Localizer
from localizer.panorama_io import read_panorama
from mapdb.dataset import read_manifest
from toploc.commands.localize import (
    db_option,
    detector_option,
    index_option,
    load_localizer,
    localizer_errors,
)
from toploc.evaluation.localization import QueryOutcome, format_confusion, score_localization


def _dataset_outcomes(localizer: Localizer, dataset: Path, progress: bool) -> list[QueryOutcome]:
    entries = read_manifest(dataset)
    outcomes = []
    for entry in tqdm(entries, desc="localize", unit="pano", disable=not progress):
        belief, observation = localizer.localize_once(read_panorama(entry.path))
        outcomes.append(
            QueryOutcome(
                entry.image, entry.room, belief.top[0], str(belief.state), observation.timing_ms
            )
        )
    return outcomes


def _leave_one_out_outcomes(localizer: Localizer, progress: bool) -> list[QueryOutcome]:
    outcomes = []
    for place in tqdm(localizer.map.places, desc="leave-one-out", disable=not progress):
        localizer.reset()
        fingerprint = localizer.map.fingerprint(place.id)
        observation = localizer.observe_fingerprint(fingerprint, exclude=place.id)
        belief = localizer.update(observation)
        outcomes.append(
            QueryOutcome(
                f"place {place.id}",
                place.room,
                belief.top[0],
                str(belief.state),
                observation.timing_ms,
            )
        )
    return outcomes


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
            outcomes = _leave_one_out_outcomes(localizer, progress)
        else:
            assert dataset is not None
            outcomes = _dataset_outcomes(localizer, dataset, progress)
        score = score_localization(outcomes)
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

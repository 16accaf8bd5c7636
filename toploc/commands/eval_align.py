"""``toploc eval align``: each compass's alignment error against distance (thesis figure 5.4)."""

from __future__ import annotations

import json
from pathlib import Path

import click
import numpy as np

from toploc.commands.eval_homing import evaluation_errors, extraction_options, load_and_extract
from toploc.evaluation.homing import COMPASSES, FeatureSettings, evaluate_alignment


@click.command("align")
@extraction_options
@click.option(
    "--bin-m",
    type=click.FloatRange(min=0, min_open=True),
    default=0.5,
    show_default=True,
    help="Width of the distance bins in metres.",
)
@click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Write the binned errors as JSON.",
)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Plot error by distance and error histograms (PNG).",
)
def align_command(
    dataset: Path,
    detector: str,
    camera: str,
    band_deg: float | None,
    rows: str,
    clahe_clip: float,
    workers: int,
    progress: bool,
    bin_m: float,
    json_path: Path | None,
    plot_path: Path | None,
) -> None:
    """Rotation between every two places of a room by each compass, against the true one.

    Compasses: histogram (eq. 5.4, 100 bins), smoothed (toploc's), matched (descriptor matches).
    Prints the mean ± standard deviation of the error (degrees) per distance bin.
    """
    with evaluation_errors():
        settings = FeatureSettings(detector, camera, band_deg, rows, clahe_clip)
        places, fingerprints, _ = load_and_extract(dataset, settings, workers, progress)
        run = evaluate_alignment(places, fingerprints, bin_m, progress)
    click.echo(
        f"{dataset}: {detector} rows={rows} band={band_deg} clahe={clahe_clip:g}; "
        "error (deg) mean ± std"
    )
    click.echo("distance_m  n     " + "".join(f"{name:>18}" for name in COMPASSES))
    reference = run.bins[COMPASSES[0]]
    for k, b in enumerate(reference):
        cells = "".join(
            f"{run.bins[name][k].mean_deg:>10.1f} ± {run.bins[name][k].std_deg:<5.1f}"
            for name in COMPASSES
        )
        click.echo(f"{b.low_m:4.1f}-{b.high_m:<4.1f}  {b.n:<5d} {cells}")
    overall = "  ".join(
        f"{name} {np.mean(np.nan_to_num(run.errors_deg[name], nan=90.0)):.1f}" for name in COMPASSES
    )
    click.echo(f"all pairs ({len(run.distances_m)}): mean error {overall}")
    if json_path is not None:
        record = {
            "dataset": str(dataset),
            "detector": detector,
            "rows": rows,
            "band_deg": band_deg,
            "bins": {name: [vars(b) for b in bins] for name, bins in run.bins.items()},
        }
        json_path.write_text(json.dumps(record, indent=2) + "\n")
    if plot_path is not None:
        from homing.thesis.eval_plots import plot_alignment

        plot_alignment(run.bins, run.errors_deg, plot_path, title=f"{dataset.name} {detector}")
        click.echo(f"wrote {plot_path}")

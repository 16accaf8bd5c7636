"""``toploc dataset``: panorama datasets on disk (rendering simulated ones, for now)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import click

from robot.conditions import CONDITIONS
from robot.worlds import WORLD_NAMES


@click.group("dataset")
def dataset() -> None:
    """Panorama datasets: a folder of images and a manifest.csv."""


@dataset.command("render")
@click.argument("out", type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--world",
    "world_name",
    type=click.Choice(WORLD_NAMES),
    required=True,
    help="Preset world to render.",
)
@click.option(
    "--spacing",
    "spacing_m",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="Capture grid spacing in metres [default: the world's].",
)
@click.option(
    "--condition",
    type=click.Choice(list(CONDITIONS)),
    default="default",
    show_default=True,
    help="Lighting, noise and added objects.",
)
@click.option(
    "--seed",
    type=int,
    default=0,
    show_default=True,
    help="Seeds the world's textures, the added objects and the noise.",
)
@click.option(
    "--heading-deg",
    type=float,
    default=0.0,
    show_default=True,
    help="Heading of every capture in its room's frame (CCW from +x).",
)
@click.option("--random-heading", is_flag=True, help="Seeded random headings instead.")
@click.option("--width", "width_px", type=click.IntRange(min=8), default=1024, show_default=True)
@click.option("--height", "height_px", type=click.IntRange(min=1), default=192, show_default=True)
@click.option(
    "--camera-height-m",
    type=click.FloatRange(min=0, min_open=True),
    default=1.0,
    show_default=True,
    help="Camera height above the floor in metres.",
)
@click.option("--grey", is_flag=True, help="Write grey images instead of colour.")
@click.option("--overwrite", is_flag=True, help="Replace the dataset in a non-empty OUT.")
def render(
    out: Path,
    world_name: str,
    spacing_m: float | None,
    condition: str,
    seed: int,
    heading_deg: float,
    random_heading: bool,
    width_px: int,
    height_px: int,
    camera_height_m: float,
    grey: bool,
    overwrite: bool,
) -> None:
    """Render a panorama at every capture place of a preset world into the folder OUT."""
    from mapdb.dataset import read_manifest
    from robot.dataset import render_dataset
    from robot.render import PanoramaCamera

    try:
        manifest = render_dataset(
            out,
            world_name,
            spacing_m=spacing_m,
            condition=condition,
            seed=seed,
            heading_deg=None if random_heading else heading_deg,
            camera=PanoramaCamera(width_px, height_px, height_m=camera_height_m),
            grey=grey,
            overwrite=overwrite,
        )
    except ValueError as error:
        raise click.ClickException(str(error)) from error
    rows = read_manifest(manifest.parent)
    click.echo(f"wrote {len(rows)} panoramas and {manifest}")
    for room, count in Counter(row.room for row in rows).items():
        click.echo(f"  {room}: {count} places")

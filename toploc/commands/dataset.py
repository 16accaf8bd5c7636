"""``toploc dataset``: panorama datasets on disk (rendering simulated ones, for now)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING, cast

import click

from homing.cameras import CAMERA_MODELS
from robot.conditions import CONDITIONS
from robot.worlds import WORLD_NAMES

if TYPE_CHECKING:
    from robot.render import PanoramaCamera, Projection

PHOTOS = "photos"


@click.group("dataset")
def dataset() -> None:
    """Panorama datasets: a folder of images and a manifest.csv."""


@dataset.command("render")
@click.argument("out", type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--world",
    "world_name",
    type=click.Choice((*WORLD_NAMES, PHOTOS)),
    required=True,
    help="Preset world to render; 'photos': real 360° photos projected onto box rooms.",
)
@click.option(
    "--rooms",
    default=None,
    help="Photo rooms to render, comma-separated [default: all 17] (--world photos only).",
)
@click.option(
    "--spacing",
    "spacing_m",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="Capture grid spacing in metres [default: the world's; photos 1.5].",
)
@click.option(
    "--condition",
    type=click.Choice(list(CONDITIONS)),
    default="default",
    show_default=True,
    help="Lighting, noise and added objects (photos: lighting and noise only).",
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
@click.option(
    "--projection",
    type=click.Choice(CAMERA_MODELS),
    default=None,
    help="Panorama projection [default: cylinder; photos equirect].",
)
@click.option(
    "--width",
    "width_px",
    type=click.IntRange(min=8),
    default=1024,
    show_default=True,
    help="Image width in pixels (360 degrees).",
)
@click.option(
    "--height",
    "height_px",
    type=click.IntRange(min=1),
    default=None,
    help="Image height [default: 192 for a cylinder, width/2 for equirect].",
)
@click.option(
    "--camera-height-m",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="Camera height above the floor in metres [default: the world's; photos 1.4].",
)
@click.option("--grey", is_flag=True, help="Write grey images instead of colour.")
@click.option("--overwrite", is_flag=True, help="Replace the dataset in a non-empty OUT.")
@click.option("--progress/--no-progress", default=True, help="Show a progress bar.")
def render(
    out: Path,
    world_name: str,
    rooms: str | None,
    spacing_m: float | None,
    condition: str,
    seed: int,
    heading_deg: float,
    random_heading: bool,
    projection: str | None,
    width_px: int,
    height_px: int | None,
    camera_height_m: float | None,
    grey: bool,
    overwrite: bool,
    progress: bool,
) -> None:
    """Render a panorama at every capture place of a preset world into the folder OUT."""
    from mapdb.dataset import read_manifest

    if rooms is not None and world_name != PHOTOS:
        raise click.UsageError("--rooms applies to --world photos only")
    try:
        camera = _camera(world_name, seed, projection, width_px, height_px, camera_height_m)
        heading = None if random_heading else heading_deg
        if world_name == PHOTOS:
            from robot.photo_dataset import PHOTO_SPACING_M, render_photo_dataset

            names = _room_list(rooms)
            spacing = PHOTO_SPACING_M if spacing_m is None else spacing_m
            manifest = render_photo_dataset(
                out, names, spacing, condition, seed, heading, camera, grey, overwrite, progress
            )
        else:
            from robot.dataset import render_dataset

            manifest = render_dataset(
                out, world_name, spacing_m, condition, seed, heading, camera, grey, overwrite,
                progress,
            )  # fmt: skip
    except ValueError as error:
        raise click.ClickException(str(error)) from error
    rows = read_manifest(manifest.parent)
    click.echo(f"wrote {len(rows)} panoramas and {manifest}")
    for room, count in Counter(row.room for row in rows).items():
        click.echo(f"  {room}: {count} places")


def _room_list(rooms: str | None) -> list[str] | None:
    """``--rooms A,B,...`` as a list of names (None: all rooms)."""
    return None if rooms is None else [r.strip() for r in rooms.split(",") if r.strip()]


def _camera(
    world_name: str,
    seed: int,
    projection: str | None,
    width_px: int,
    height_px: int | None,
    camera_height_m: float | None,
) -> PanoramaCamera:
    """The camera of ``toploc dataset render``: options, else the world's defaults."""
    from robot.photo_room import CAPTURE_HEIGHT_M
    from robot.render import PanoramaCamera
    from robot.worlds import make_world

    if projection is None:
        projection = "equirect" if world_name == PHOTOS else "cylinder"
    if height_px is None:
        height_px = width_px // 2 if projection == "equirect" else 192
    if camera_height_m is None:
        if world_name == PHOTOS:
            camera_height_m = CAPTURE_HEIGHT_M
        else:
            camera_height_m = make_world(world_name, seed).camera_height_m
    kind = cast("Projection", projection)
    return PanoramaCamera(width_px, height_px, height_m=camera_height_m, projection=kind)


@dataset.command("perturb")
@click.argument("source", type=click.Path(file_okay=False, exists=True, path_type=Path))
@click.argument("out", type=click.Path(file_okay=False, path_type=Path))
@click.option("--rooms", default=None, help="Rooms to copy, comma-separated [default: all].")
@click.option(
    "--roll-deg",
    type=float,
    default=0.0,
    show_default=True,
    help="Turn every panorama by this yaw (column 0 moves clockwise; headings follow).",
)
@click.option("--random-roll", is_flag=True, help="A seeded random roll per image instead.")
@click.option(
    "--width",
    "width_px",
    type=click.IntRange(min=16),
    default=None,
    help="Resize to this width, the aspect kept [default: as is].",
)
@click.option(
    "--condition",
    type=click.Choice(list(CONDITIONS)),
    default="default",
    show_default=True,
    help="Lighting and sensor noise (added objects do not apply to an image).",
)
@click.option(
    "--jpeg-quality",
    type=click.IntRange(1, 100),
    default=90,
    show_default=True,
    help="JPEG quality of the copies.",
)
@click.option("--png", is_flag=True, help="Write lossless PNG copies instead of JPEG.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seeds rolls and noise.")
@click.option("--overwrite", is_flag=True, help="Replace the dataset in a non-empty OUT.")
@click.option("--progress/--no-progress", default=True, help="Show a progress bar.")
def perturb(
    source: Path,
    out: Path,
    rooms: str | None,
    roll_deg: float,
    random_roll: bool,
    width_px: int | None,
    condition: str,
    jpeg_quality: int,
    png: bool,
    seed: int,
    overwrite: bool,
    progress: bool,
) -> None:
    """Copy the panoramas of SOURCE (a manifest, or one sub-folder per room) into OUT as grey
    images, each turned in yaw, resized and under a capture condition: views of the same places
    that a map built from SOURCE did not store (e.g. from real 360° photos with one capture
    point each)."""
    from localizer.panorama_io import PanoramaError
    from mapdb.dataset import read_manifest
    from mapdb.errors import ManifestError
    from robot.conditions import get_condition
    from robot.perturb import Perturbation, perturb_dataset

    if random_roll and roll_deg != 0.0:
        raise click.UsageError("give --roll-deg or --random-roll, not both")
    names = _room_list(rooms)
    perturbation = Perturbation(
        roll_deg=None if random_roll else roll_deg,
        width_px=width_px,
        condition=get_condition(condition),
        jpeg_quality=None if png else jpeg_quality,
    )
    try:
        manifest = perturb_dataset(source, out, perturbation, names, seed, overwrite, progress)
    except (ValueError, ManifestError, PanoramaError, OSError) as error:
        raise click.ClickException(str(error)) from error
    rows = read_manifest(manifest.parent)
    click.echo(f"wrote {len(rows)} panoramas and {manifest}")

"""Draw the README's figure: the `building` world's floor plan and the panoramas the simulated
robot sees from the same spot in its two look-alike offices.

    python docs/figures/make_readme_figure.py [OUT.png]

Writes ``docs/figures/building.png`` by default (about 1000 x 360 px). Deterministic: the world
is ``building`` with seed 0, the one the demo renders (doors drawn as gaps in the plan); the
panoramas are rendered by toploc's own ray caster (``robot.render``) at the default 1024 x 192
cylinder, heading north, so the door to the corridor is in the middle of each image.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.patches import Rectangle

from robot.render import render_panorama
from robot.scene import build_scene
from robot.world import Pose2D
from robot.worlds import make_world

OUT = Path(__file__).resolve().with_name("building.png")
OFFICES = ("office_a", "office_b")
SPOT_IN_ROOM_M = (2.9, 1.2)
"""The spot in each office's own frame: 1 m in front of its door (room-frame x 2.9 m in both)."""
HEADING_RAD = math.pi / 2
"""North (+y, away from the door): column 0 looks north, the door is at the image's centre."""


def main(out: Path = OUT) -> Path:
    """Render the figure into ``out`` (PNG) and return its path."""
    world = make_world("building", 0)
    scene = build_scene(world)
    fig = plt.figure(figsize=(10.0, 3.6), dpi=100)
    grid = fig.add_gridspec(2, 2, width_ratios=(1.0, 2.1), hspace=0.45, wspace=0.08)

    plan = fig.add_subplot(grid[:, 0])
    for room in world.rooms:
        x0, x1, y0, y1 = room.bounds_m
        look_alike = room.name in OFFICES
        plan.add_patch(
            Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor="#dbe8f5" if look_alike else "#eeeeee",
                      edgecolor="#333333", linewidth=1.0)
        )  # fmt: skip
        label_y_m = y1 - 0.7 if look_alike else (y0 + y1) / 2
        plan.text((x0 + x1) / 2, label_y_m, room.name, ha="center", fontsize=8)
    for door in world.doors:
        wall = world.door_wall(door)
        along = (door.center_m - door.width_m / 2, door.center_m + door.width_m / 2)
        across = (wall.coord_m, wall.coord_m)
        xs, ys = (across, along) if wall.axis == 0 else (along, across)
        plan.plot(xs, ys, color="white", linewidth=3.0, solid_capstyle="butt")
    for name in OFFICES:
        spot = world.room(name).to_building(*SPOT_IN_ROOM_M)
        plan.plot(*spot, "o", color="#c0392b", markersize=5)
        plan.annotate("", xy=(spot[0], spot[1] + 0.8), xytext=spot,
                      arrowprops={"arrowstyle": "->", "color": "#c0392b"})  # fmt: skip
    plan.set_xlim(-0.5, 14.5)
    plan.set_ylim(-5.5, 6.2)
    plan.set_aspect("equal")
    plan.set_xlabel("x (m)", fontsize=8)
    plan.set_ylabel("y (m)", fontsize=8)
    plan.tick_params(labelsize=7)
    plan.set_title("the building world (seed 0)", fontsize=9)

    for row, name in enumerate(OFFICES):
        x_m, y_m = world.room(name).to_building(*SPOT_IN_ROOM_M)
        image = render_panorama(scene, Pose2D(x_m, y_m, HEADING_RAD))
        axis = fig.add_subplot(grid[row, 1])
        axis.imshow(image)
        axis.set_xticks([0, image.shape[1] // 2, image.shape[1] - 1], ["north", "south (door)", ""])
        axis.set_yticks([])
        axis.tick_params(labelsize=7)
        axis.set_title(f"panorama at the red dot in {name} (360°, 1024 x 192)", fontsize=9)

    fig.savefig(out, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return out


if __name__ == "__main__":
    print(main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT))

"""Benchmark the whole loop on maps recorded the way users record them (issue 19, section 1).

Per world and ``K`` (places per room): a map is recorded in the rendered world as the README's
loop records one (:mod:`toploc.evaluation.recorded_maps`: K places per room, a random turn and
a short drive between two, the robot's odometry as the pose, the world's doors as edges, then
calibrated), and the simulated robot is kidnapped ``--trials`` times into the world's look-alike
rooms (``building``: office_a/office_b; ``house``: the twin bedrooms and bathrooms; with
``--every-room``, into each room of the world in turn) and localizes actively
(:func:`toploc.evaluation.kidnap.run_kidnappings`). ``--first-looks N`` instead kidnaps N
times into every room and scores the single frame taken there, without driving.

Reported per map: the five outcomes of the first look (a single frame off the map's places)
and of the final belief, how many trials drove, the mean drives and distance, seconds per
trial, and the reliability of the final answers (of those stated at >= 0.9, how many right;
the Brier score). Recorded maps are cached under ``--cache-dir`` (delete it to re-record).

Held out: choices of toploc's likelihood and policy were made on world seeds 0 and 1 (record
seeds 0, 1, 2) and then on world seed 2 (record seed 3); ``--world-seed 3 --record-seed 4`` was
measured once with the final code, then used to try a rule that was not kept; the look-alike
test by appearance was chosen on world seeds 0-3 (record seeds 1-4) and measured held out on
world seeds 4 and 5 (record seeds 5 and 6) (docs/results.md). Session 14 measured main on world
seeds 6 and 7 (record seeds 7 and 8), wrote the "outdone" pair rule looking at seed 6 and
judged it on seed 7. Session 15 judged the active loop's "one view, one piece of evidence" on
world seed 8 (record seed 9), the change written on world seed 4, then wrote the "standout" pair
rule looking at seed 8 and judged it on seeds 9 and 10. Session 16 wrote the "far above
chance" standout looking at seed 9's building (K = 3) and judged it on world seed 11 (record
seed 12). Session 18 (``--drive``, recorded routes) chose its rules on world seed 11, then on
seeds 12 and 13 (record seeds 13, 14), and judged the last on seed 14 (record seed 15); the
house of seeds 12-14 was not run. Sessions 19-23 used world seeds 15-26. Session 24 wrote
its route-check and appearance rules looking at world seeds 26 and 27 (record seeds 27, 28) and
judged them on seed 28, and its route-end rule on seed 29 (record seeds 29, 30). Sessions 25
and 26 wrote their changes on world seeds 30, 31 and 33 and judged them on seed 34; session 27
wrote its changes on seeds 31, 34 and 35 and judged them on seed 36 (record seeds one up).
Sessions 28-30 wrote their changes on world seeds 35, 37, 39 and 43 and judged them on 41, 43
and 45. Session 31 wrote its changes on seeds 43 and 45 (and, kidnapping into every room,
35-45) and judged them on seed 47 (record seed 48). Session 32 wrote its changes on seeds
35-47 and 49 and judged them on seed 51 (record seed 52). Session 33 wrote its changes on
seeds 37-47 and judged them on seed 53 (record seed 54). Session 34 wrote its turn compass on
seeds 39, 43 and 47 and judged it on seed 55 (record seed 56). Session 35 wrote its step
towards what a lost robot matched on the lost robots of seeds 39-53 and judged it on seed 57
(record seed 58; also seed 55, whose lost robots it had not looked at). Session 36 wrote its
end at a place of the named room on single looks at the recorded maps of seeds 35-57 and
judged it on seeds 59 and 61 (record seeds 60 and 62). Session 37 wrote its step into the
room from a place recorded past a door on the two sure-and-wrong door answers of seeds 51 and
59 and judged it on seed 63 (record seed 64), then measured its final code once on seed 65
(record seed 66), no change written on it. Session 38 wrote its step out of a check that
could not start on seed 63's trial 18 (and looked at seed 63's trials 6, 13 and 16) and
judged it on seeds 67 and 69 (record seeds 68 and 70); it looked at seed 67's building trial 0
to see why a door search it did not keep failed there; its retry of a check that could not
start was written on seed 63's trial 6 and judged on seed 71 (record seed 72), its final code
measured once more on seed 69. Session 39 measured main, untouched, on world seeds 73 (K = 1,
2, 3 and 5), 75 and 77 (record seeds one up; K = 2), then looked at seed 75's building trial
3, seed 59's trial 2 and seed 71's every-room run for two changes it did not keep.
Session 40 measured main, untouched, on world seeds 79 and 81 (K = 1 and 2; record seeds
one up), and looked again at the homings of seed 75's building trial 3 and seed 71's
every-room trials 24 and 39, and at seed 81's house (K = 1) lost trials 0 and 5; it measured
main on seed 83 (K = 1) as a baseline and looked at its house trial 5 (sure and wrong).
Session 41 wrote its step-in frame fix on seed 83's house trial 5 and judged it on seed 85
(record seed 86; K = 1 and 2), then wrote its checks by routes that end elsewhere on seed 85's
house bathroom trials (K = 1; trial 2 looked at) and seed 83's, looked at seed 83's trial 1
and seed 85's trial 0 for a change it did not keep, and judged the code on seed 87 (record
seed 88) and, with two places per room, seed 89 (record seed 90); a review's mends to the
re-checks were measured again on seeds 83 and 85 only. Session 42 changed no behaviour (it
ran seed 87's building, K = 2, and seed 85's house, K = 1, before and after to show it), tried
a homing it did not keep on seed 87's building (K = 2) and seed 81's house (K = 1), looked at
the homings of seed 87's building trial 18, and measured main once on seed 91 (record seed
92; K = 1 and 2), none of whose trials it looked into, and on seed 93's building (record seed
94; K = 1 and 2), whose one-place trial 1 it then traced and wrote a change on (a way back that
held keeps the belief), judged on seed 91's four runs again (all the same: the case did not
arise). Session 43 measured main once on world seeds 95 (K = 1 and 2), 97 and 99 (K = 1;
record seeds one up), wrote its fold of a held way back on seed 93's building (K = 1), its
doubt of an unreachable one-place room on seed 95's building (K = 1, trial 4) and its doubt
after a held miss on seed 97's building (K = 1, trial 15), and judged them on seeds 91, 95's
house and 99 (K = 1). Sessions 44-46 ran world seeds 95 and 101-135 (docs/results.md says
which, and what each was used for). Session 47 wrote its rule for a frame on a room's place
looking at seed 133's house (K = 2; trials 4, 8 and 16 traced) and judged it on seed 137
(record seed 138; K = 2), recorded after the change; with ``--unmapped`` it ran seed 133's
house without its kitchen, then without its study. Session 48 wrote its lift of a look-alike
by its own look-alikes only looking at seed 137's building (K = 2; trials 4, 6, 10 and 18
traced), measured it on seed 129's building (K = 1), and judged it on seeds 139 (building,
K = 2), 145 (building, K = 2) and 157 (building, K = 2; house, K = 1), recorded for the first
time; of seeds 141-161 it recorded all four maps (K = 1, 2) and chose those whose look-alike
groups are not all pairs, before running any. World seeds 163 and up have not been run.

``--unmapped ROOM`` records the map without ROOM and kidnaps into ROOM only: the robot is where
the map has no room, so any ``localized`` answer while it stands there is wrong.

    python benchmarks/bench_recorded_maps.py [--worlds building,house] [--places 1,2,3,5]
        [--trials 20] [--record-seed 0] [--world-seed 0] [--drive] [--declared] [--advised
        [--advised-offset M]] [--every-room | --unmapped ROOM] [--first-looks N]
        [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from localizer.belief import RoomBelief
from localizer.localizer import Localizer
from localizer.lookalikes import pairs_without_counterparts
from robot.worlds import make_world
from toploc.evaluation.kidnap import KIDNAP_ROOMS, Trial, describe_endings, run_kidnappings
from toploc.evaluation.localization import OUTCOMES, count_outcomes
from toploc.evaluation.recorded_maps import record_counterparts, record_map
from toploc.maps import cache_dir, calibrate_map, kidnapped_robot, load_map

SHORT = {
    "right_localized": "R+L",
    "right_ambiguous": "R+A",
    "wrong_localized": "W+L",
    "wrong_ambiguous": "W+A",
    "lost": "lost",
}


TWINS: dict[str, tuple[tuple[str, str], ...]] = {
    "building": (("office_a", "office_b"),),
    "house": (("bedroom_a", "bedroom_b"), ("bathroom_a", "bathroom_b")),
}
"""The look-alike rooms of each world, as a user who knows them declares them (``--declared``)."""


def first_outcome(trial: Trial) -> str:
    """The outcome of the trial's first look (before any drive)."""
    return look_outcome(trial.result.first, trial.true_room)


def look_outcome(belief: RoomBelief, true_room: str) -> str:
    """Which of :data:`OUTCOMES` ``belief`` is for a robot in ``true_room``."""
    if str(belief.state) == "lost":
        return "lost"
    return f"{'right' if belief.top[0] == true_room else 'wrong'}_{belief.state}"


def recorded_db(
    cache: Path,
    world: str,
    world_seed: int,
    places: int,
    record_seed: int,
    advised: bool,
    declared: bool = False,
    advised_offset_m: float = 0.0,
    drive: bool = False,
    unmapped: str | None = None,
) -> Path:
    """The cached recorded map (recorded if missing), calibrated again by the code being
    measured; ``drive``: recorded on one drive through the doors, the legs stored
    (:func:`~toploc.evaluation.recorded_maps.record_drive`), else room by room;
    ``declared``: then the world's twins (:data:`TWINS`) declared as ``toploc map
    lookalike`` does; ``advised``: then two places at the same two spots of each look-alike
    pair's rooms, as ``toploc map info`` advises; ``unmapped``: a room of the world left out of
    the map."""
    suffix = ("-drive" if drive else "") + ("-declared" if declared else "")
    suffix += f"-no-{unmapped}" if unmapped else ""
    suffix += "-advised" if advised else ""
    suffix += f"-off{advised_offset_m:g}" if advised and advised_offset_m else ""
    name = f"recorded-{world}-w{world_seed}-k{places}-r{record_seed}{suffix}"
    db = cache / name / "map.db"
    start = time.perf_counter()
    if not db.exists():
        db.parent.mkdir(parents=True, exist_ok=True)
        scene = make_world(world, world_seed)
        rooms = [room.name for room in scene.rooms if room.name != unmapped]
        record_map(scene, places, record_seed, db, rooms=rooms, progress=True, drive=drive)
        for pair in TWINS[world] if declared else ():
            calibrate_map(db, declare=pair)
        if advised:
            loaded = load_map(db)
            if loaded.likelihood is not None:
                room_of = {place.id: place.room for place in loaded.places}
                likelihood = loaded.likelihood
                pairs = pairs_without_counterparts(
                    likelihood.lookalikes, likelihood.counterparts, room_of
                )
                record_counterparts(scene, pairs, record_seed, db, offset_m=advised_offset_m)
        print(f"recorded {db} in {time.perf_counter() - start:.0f} s")
    else:
        calibrate_map(db)
        print(f"calibrated {db} in {time.perf_counter() - start:.0f} s")
    return db


def args_db(args: argparse.Namespace, world: str, places: int) -> Path:
    """:func:`recorded_db` for the command line's options."""
    return recorded_db(
        Path(args.cache_dir),
        world,
        args.world_seed,
        places,
        args.record_seed,
        args.advised,
        args.declared,
        args.advised_offset,
        args.drive,
        args.unmapped,
    )


def run_one(args: argparse.Namespace, world: str, places: int) -> dict[str, Any]:
    db = args_db(args, world, places)

    def show(trial: Trial) -> None:
        if args.verbose:
            print(f"  {trial.describe()}  first {first_outcome(trial)}")

    every = tuple(room.name for room in make_world(world, args.world_seed).rooms)
    into = (args.unmapped,) if args.unmapped else every if args.every_room else None
    run = run_kidnappings(
        world,
        args.trials,
        policy=args.policy,
        seed=args.record_seed,
        db_path=db,
        world_seed=args.world_seed,
        progress=False,
        on_trial=show,
        rooms=into,
    )
    totals = run.totals()
    totals["first_outcomes"] = count_outcomes(first_outcome(t) for t in run.trials)
    likelihood = load_map(db).likelihood
    lookalikes = {
        "lookalikes": [list(p) for p in likelihood.lookalikes] if likelihood else [],
        "counterparts": len(likelihood.counterparts) if likelihood else 0,
    }
    row = {"world": world, "places_per_room": places, "advised": args.advised, "db": str(db)}
    row["kidnapped_into"] = (
        f"{args.unmapped} (not in the map)"
        if args.unmapped
        else "every room"
        if args.every_room
        else "look-alikes"
    )
    return row | lookalikes | {"run": run.to_json(), "totals": totals}


def first_looks(args: argparse.Namespace, world: str, places: int) -> dict[str, Any]:
    """``args.first_looks`` kidnappings into every room of ``world`` in turn (trial ``i``
    seeded ``record_seed * 100_000 + i``, as :func:`run_kidnappings`), one look each and no
    drive: the five outcomes of a single frame off the map's places, how many of the answers
    stated at >= 0.9 were right, and each confidently wrong one."""
    db = args_db(args, world, places)
    scene = make_world(world, args.world_seed)
    rooms = [room.name for room in scene.rooms]
    localizer = Localizer(load_map(db))
    names = " ".join(f"{SHORT[o]:>4s}" for o in OUTCOMES)
    print(f"| world | K | first look {names} | >=0.9 right |")
    outcomes, sure, sure_right, wrong = [], 0, 0, []
    for i in range(args.first_looks):
        robot = kidnapped_robot(scene, rooms[i % len(rooms)], args.record_seed * 100_000 + i, db)
        localizer.reset()
        belief = localizer.update(localizer.observe(robot.capture().image))
        truth = robot.true_room()
        outcomes.append(look_outcome(belief, truth))
        if outcomes[-1] != "lost" and belief.top[1] >= 0.9:
            sure, sure_right = sure + 1, sure_right + (belief.top[0] == truth)
        if outcomes[-1] == "wrong_localized":
            wrong.append({"trial": i, "room": truth, "said": belief.top[0], "p": belief.top[1]})
    counts = count_outcomes(outcomes)
    print(
        f"| {world} | {places} | {' '.join(f'{counts[o]:4d}' for o in OUTCOMES)} "
        f"| {sure_right}/{sure} |"
    )
    for item in wrong:
        print(f"    trial {item['trial']}: in {item['room']}, said {item['said']} {item['p']:.3f}")
    return {"world": world, "places_per_room": places, "db": str(db), "first_looks": counts}


def confident(totals: dict[str, Any]) -> str:
    """``right/n`` of the answers stated at >= 0.9."""
    bins = [b for b in totals["reliability"]["bins"] if b["low"] >= 0.9 and b["n"]]
    n = sum(b["n"] for b in bins)
    right = sum(round(b["n"] * b["fraction_right"]) for b in bins)
    return f"{right}/{n}"


def print_table(rows: list[dict[str, Any]]) -> None:
    names = " ".join(f"{SHORT[o]:>4s}" for o in OUTCOMES)
    print(
        f"| world | K | first look {names} | final {names} | drove | drives | m | s "
        "| >=0.9 right | Brier | ended | route checks own +/-, other +/- | elsewhere "
        "| R+L where put |"
    )
    for row in rows:
        t = row["totals"]
        first = " ".join(f"{t['first_outcomes'][o]:4d}" for o in OUTCOMES)
        final = " ".join(f"{t['outcomes'][o]:4d}" for o in OUTCOMES)
        print(
            f"| {row['world']} | {row['places_per_room']}{'+2' if row['advised'] else ''} "
            f"| {first} | {final} | "
            f"{t['drove']}/{t['trials']} | {t['mean_steps']:.2f} | {t['mean_distance_m']:.2f} | "
            f"{t['mean_seconds']:.1f} | {confident(t)} | {t['reliability']['brier']:.3f} "
            f"| {describe_endings(t['endings'])} | {_checks(t['route_checks'])} "
            f"| {t['ended_elsewhere']} | {t['right_where_put']} |"
        )


def _checks(counts: dict[str, int]) -> str:
    """``12/1, 0/9``: own room's checks confirmed/refuted, then the other rooms'."""
    own = f"{counts['own_confirmed']}/{counts['own_refuted']}"
    return f"{own}, {counts['other_confirmed']}/{counts['other_refuted']}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", default="building,house")
    parser.add_argument("--places", default="1,2,3,5", help="places per room, comma-separated")
    parser.add_argument(
        "--trials", type=int, default=20, help="kidnappings per map; 0: record the maps only"
    )
    parser.add_argument("--policy", default="separating")
    parser.add_argument("--record-seed", type=int, default=0)
    parser.add_argument("--world-seed", type=int, default=0)
    parser.add_argument("--cache-dir", default=str(cache_dir() / "bench-recorded"))
    parser.add_argument("--json", type=Path)
    parser.add_argument(
        "--advised",
        action="store_true",
        help="after recording, two more places at two spots of each look-alike pair's rooms",
    )
    parser.add_argument(
        "--advised-offset",
        type=float,
        default=0.0,
        metavar="M",
        help="with --advised: the second twin's place stands M metres off the spot (by eye)",
    )
    parser.add_argument(
        "--declared",
        action="store_true",
        help="after recording, the world's twins declared (toploc map lookalike)",
    )
    parser.add_argument(
        "--drive",
        action="store_true",
        help="record each map on one drive through the doors (legs stored), not room by room",
    )
    parser.add_argument(
        "--every-room",
        action="store_true",
        help="kidnap into every room of the world in turn, not only its look-alikes",
    )
    parser.add_argument(
        "--first-looks",
        type=int,
        default=0,
        metavar="N",
        help="instead of the loop: N kidnappings into every room, one look each, no drive",
    )
    parser.add_argument(
        "--unmapped",
        metavar="ROOM",
        help="record the map without ROOM and kidnap into ROOM only: any answer it states "
        "as localized while the robot is there is wrong",
    )
    parser.add_argument("-v", "--verbose", action="store_true")
    args = parser.parse_args()
    worlds = args.worlds.split(",")
    for world in worlds:
        if world not in KIDNAP_ROOMS:
            parser.error(
                f"world {world!r} has no look-alike rooms; choose from {list(KIDNAP_ROOMS)}"
            )
    if args.trials < 0:
        parser.error(f"--trials must be >= 0, got {args.trials}")
    for world in worlds if args.unmapped else ():
        names = [room.name for room in make_world(world, args.world_seed).rooms]
        if args.unmapped not in names:
            parser.error(f"--unmapped: world {world!r} has no room {args.unmapped!r}; {names}")
    rows = []
    for world in worlds:
        for places in (int(k) for k in args.places.split(",")):
            print(f"{world}, {places} places per room:")
            if args.first_looks:
                rows.append(first_looks(args, world, places))
                continue
            if not args.trials:  # record (or calibrate) the map only
                args_db(args, world, places)
                continue
            rows.append(run_one(args, world, places))
            print_table(rows[-1:])
    if not rows:
        return
    if args.first_looks:
        if args.json:
            args.json.write_text(json.dumps(rows, indent=1) + "\n")
            print(f"wrote {args.json}")
        return
    print()
    print(
        f"recorded maps, world seed {args.world_seed}, record seed {args.record_seed}, "
        f"{args.trials} kidnappings each"
        f"{' into every room' if args.every_room and not args.unmapped else ''}"
        f"{f' into {args.unmapped}, a room the map lacks' if args.unmapped else ''}"
        f", policy {args.policy}"
        f"{', on one drive' if args.drive else ''}"
        f"{', twins declared' if args.declared else ''}"
        f"{', advised (2 counterpart places per look-alike pair)' if args.advised else ''}"
    )
    print_table(rows)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

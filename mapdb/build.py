"""Building a map from a dataset: hash, extract in worker processes, write each place whole.

The pipeline (``build_map``):

1. Hash every image (SHA-256 of the file bytes) in the parent; an image already in the map, or
   repeated in the dataset, is *skipped* and said so; an unreadable file *failed*.
2. Extract fingerprints with the injected ``extract(path) -> list[Fingerprint]`` in a spawned
   process pool (:func:`mapdb.workers.spawn_process_pool`; at most ``2 * workers`` images in
   flight, so memory stays bounded); ``workers <= 1`` runs in-process. ``extract`` must be
   picklable (a module-level function or a ``functools.partial`` of one) and raises (e.g.
   ``ValueError``) for a bad image: *failed*.
3. The parent writes each place with its fingerprints in one transaction (all or nothing).

Interrupting (Ctrl-C) or killing the process loses at most the places not yet committed; every
committed place is complete, and re-running the build adds the rest. Database faults (full disk,
lock, read-only) and a dead worker process stop the build with a
:class:`~mapdb.errors.MapDatabaseError`.
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import closing
from dataclasses import dataclass, field
from datetime import UTC, datetime
from enum import Enum
from pathlib import Path

from tqdm import tqdm

from mapdb.database import MapDatabase
from mapdb.dataset import ManifestEntry, NotARegularFileError, sha256_file
from mapdb.errors import BuildAbortedError, DuplicatePlaceError
from mapdb.records import Fingerprint, NewPlace
from mapdb.workers import WorkerDiedError, deferred_signals, spawn_process_pool, stop_workers

Extractor = Callable[[Path], list[Fingerprint]]

SIGNAL_POLL_S = 0.1
"""How often the parallel build looks for a Ctrl-C while it waits for its workers, seconds."""


class Status(Enum):
    """What happened to one image of a build."""

    ADDED = "added"
    SKIPPED = "skipped"
    FAILED = "failed"


@dataclass(frozen=True)
class Outcome:
    """The result for one image: its manifest name, status, place id (if any) and why."""

    image: str
    status: Status
    place_id: int | None = None
    message: str = ""
    warning: bool = False
    """A skip worth telling without ``--verbose`` (an image listed twice)."""

    def describe(self) -> str:
        """One line for a log: ``"<status> <image>: <message>"``."""
        return f"{self.status.value} {self.image}: {self.message}"


@dataclass
class BuildReport:
    """Outcomes of a build, in the order they happened; ``interrupted`` after Ctrl-C."""

    outcomes: list[Outcome] = field(default_factory=list)
    interrupted: bool = False

    def count(self, status: Status) -> int:
        """Number of images with ``status``."""
        return sum(1 for outcome in self.outcomes if outcome.status is status)

    @property
    def ok(self) -> bool:
        """True when no image failed and the build ran to the end."""
        return not self.interrupted and self.count(Status.FAILED) == 0

    def summary(self) -> str:
        """``"added A, skipped S, failed F"`` (plus ``", interrupted"``)."""
        text = ", ".join(f"{s.value} {self.count(s)}" for s in Status)
        return text + (", interrupted" if self.interrupted else "")


@dataclass(frozen=True)
class _Job:
    entry: ManifestEntry
    image_sha256: str


def file_mtime_utc(path: Path) -> str | None:
    """The file's modification time as ISO-8601 UTC text (the capture time we can know)."""
    try:
        mtime_s = path.stat().st_mtime
    except OSError:
        return None
    return datetime.fromtimestamp(mtime_s, UTC).isoformat(timespec="seconds")


def _error_text(error: BaseException) -> str:
    """A one-line reason; the type name is added unless it is a plain value or OS error."""
    text = str(error) or type(error).__name__
    return text if isinstance(error, ValueError | OSError) else f"{type(error).__name__}: {text}"


def _at_line(entry: ManifestEntry, text: str) -> str:
    """``text`` prefixed with the entry's manifest line (none for an image given directly)."""
    return f"line {entry.line}: {text}" if entry.line > 0 else text


def _row(entry: ManifestEntry) -> str:
    """How a message names another entry: its manifest line and image, or its image alone."""
    return f"line {entry.line} ({entry.image})" if entry.line > 0 else entry.image


def _pose(entry: ManifestEntry) -> tuple[str, float | None, float | None, float | None]:
    return (entry.room, entry.x_m, entry.y_m, entry.heading_deg)


def _conflict(entry: ManifestEntry, other: ManifestEntry) -> str:
    """Why two rows of the same image cannot both be right, naming both lines."""
    return _at_line(
        entry,
        f"same image as {_row(other)} but in room {entry.room!r} at "
        f"{_pose(entry)[1:]} against room {other.room!r} at {_pose(other)[1:]}: conflicting "
        f"duplicates, neither is imported; keep the right row",
    )


def plan_jobs(
    entries: Iterable[ManifestEntry], known_hashes: dict[str, int]
) -> tuple[list[_Job], list[Outcome]]:
    """Hash each image; return the jobs to extract and the outcomes already decided.

    Decided: unreadable or not a regular file (failed), already in the map (skipped), listed
    again with the same room and pose (skipped, with a warning), listed again with another room
    or pose (both rows failed: conflicting duplicates, neither is imported).
    """
    decided: list[Outcome] = []
    first: dict[str, ManifestEntry] = {}
    conflicting: dict[str, ManifestEntry] = {}  # image -> the first row that contradicts it
    for entry in entries:
        try:
            sha = sha256_file(entry.path)
        except OSError as error:
            reason = f"cannot read {entry.path}: {error.strerror or error}"
            decided.append(Outcome(entry.image, Status.FAILED, message=_at_line(entry, reason)))
            continue
        except NotARegularFileError as error:
            message = _at_line(entry, f"{error}; only regular files are read")
            decided.append(Outcome(entry.image, Status.FAILED, message=message))
            continue
        if sha in known_hashes:
            place_id = known_hashes[sha]
            message = f"already in the map as place {place_id}"
            decided.append(Outcome(entry.image, Status.SKIPPED, place_id, message))
        elif sha not in first:
            first[sha] = entry
        elif _pose(first[sha]) == _pose(entry):
            message = _at_line(entry, f"exact duplicate of {_row(first[sha])}, skipped")
            decided.append(Outcome(entry.image, Status.SKIPPED, message=message, warning=True))
        else:
            conflicting.setdefault(sha, entry)
            decided.append(
                Outcome(entry.image, Status.FAILED, message=_conflict(entry, first[sha]))
            )
    jobs = []
    for sha, entry in first.items():
        if sha in conflicting:
            message = _conflict(entry, conflicting[sha])
            decided.append(Outcome(entry.image, Status.FAILED, message=message))
        else:
            jobs.append(_Job(entry, sha))
    return jobs, decided


def _extract_serial(
    jobs: Sequence[_Job], extract: Extractor
) -> Generator[tuple[_Job, list[Fingerprint] | Exception], None, None]:
    for job in jobs:
        try:
            yield job, extract(job.entry.path)
        except Exception as error:  # a bad image must not stop the others
            yield job, error


def _extract_parallel(
    jobs: Sequence[_Job], extract: Extractor, workers: int
) -> Generator[tuple[_Job, list[Fingerprint] | Exception], None, None]:
    """Results in the order of ``jobs``, with at most ``2 * workers`` jobs submitted or
    waiting to be yielded at a time. In the order they completed instead, the places of two
    builds of one folder got other ids, and the map other answers: the calibration and the
    retrieval index read the places in id order (the bare house's 35 places, built three times:
    fits `-4.31 + 1.21 log(1+n)` and `-4.27 + 1.18` with general motion, `-4.49 + 1.20` planar;
    9, 9 and 11 of its 50 queries right but ambiguous).

    Ctrl-C (and a ``SIGTERM`` handler) takes effect here, between two waits of at most
    :data:`SIGNAL_POLL_S`, never inside the pool's code (see :func:`deferred_signals`); a place
    being written when it comes is written whole first.
    """
    pending = iter(enumerate(jobs))
    in_flight: dict[Future[list[Fingerprint]], tuple[int, _Job]] = {}
    ready: dict[int, tuple[_Job, list[Fingerprint] | Exception]] = {}
    next_out = 0
    finished = False
    with deferred_signals() as check_signals:
        pool = spawn_process_pool(workers)

        def submit_next() -> None:
            item = next(pending, None)
            if item is not None:
                in_flight[pool.submit(extract, item[1].entry.path)] = item

        try:
            for _ in range(2 * workers):
                submit_next()
            while in_flight or ready:
                if next_out in ready:
                    job, result = ready.pop(next_out)
                    next_out += 1
                    submit_next()
                    yield job, result
                    check_signals()
                    continue
                done, _ = wait(in_flight, timeout=SIGNAL_POLL_S, return_when=FIRST_COMPLETED)
                check_signals()
                if not done:  # what has come is written first
                    pool.check_workers()
                for future in done:
                    index, job = in_flight.pop(future)
                    try:
                        extracted: list[Fingerprint] | Exception = future.result()
                    except BrokenProcessPool as error:
                        raise pool.named(error) from error
                    except Exception as error:  # raised by extract in the worker
                        extracted = error
                    ready[index] = (job, extracted)
            finished = True
        finally:
            if finished:
                pool.shutdown(wait=True)
            else:  # interrupted, or a fault: the workers' results are no longer wanted
                stop_workers(pool)


def build_map(
    map_db: MapDatabase,
    entries: Sequence[ManifestEntry],
    extract: Extractor,
    *,
    workers: int = 2,
    progress: bool = True,
    on_outcome: Callable[[Outcome], None] | None = None,
) -> BuildReport:
    """Add every entry's panorama to ``map_db`` (see the module docstring); return the report.

    ``on_outcome`` is called for every image, in the entries' order, once its fate is known
    (for logging; use ``tqdm.write`` to print under the progress bar). Ctrl-C ends the build
    cleanly with ``report.interrupted`` set: with ``workers <= 1`` the place being written, if
    any, is rolled back; with worker processes it is written whole first (see
    :func:`_extract_parallel`).
    """
    report = BuildReport()

    def record(outcome: Outcome, bar: tqdm) -> None:
        report.outcomes.append(outcome)
        bar.update(1)
        if on_outcome is not None:
            on_outcome(outcome)

    with tqdm(total=len(entries), unit="pano", disable=not progress, leave=False) as bar:
        try:
            jobs, decided = plan_jobs(entries, map_db.image_hashes())
            for outcome in decided:
                record(outcome, bar)
            if workers <= 1 or len(jobs) <= 1:
                results = _extract_serial(jobs, extract)
            else:
                results = _extract_parallel(jobs, extract, workers)
            with closing(results):
                for job, result in results:
                    record(_store(map_db, job, result), bar)
        except KeyboardInterrupt:
            report.interrupted = True
        except BrokenProcessPool as error:
            added = report.count(Status.ADDED)
            how = f": {error}" if isinstance(error, WorkerDiedError) else f" ({error})"
            raise BuildAbortedError(
                f"a feature-extraction worker process died{how}; the {added} places "
                f"added to {map_db.path} are complete: re-run the build to continue",
                map_db.path,
            ) from error
    return report


def _store(map_db: MapDatabase, job: _Job, result: list[Fingerprint] | Exception) -> Outcome:
    """Write one extracted panorama as a place (one transaction) and say what happened."""
    entry = job.entry
    if isinstance(result, Exception):
        return Outcome(entry.image, Status.FAILED, message=_error_text(result))
    try:
        place = NewPlace(
            room=entry.room,
            image_sha256=job.image_sha256,
            source=str(entry.path.resolve()),
            x_m=entry.x_m,
            y_m=entry.y_m,
            heading_deg=entry.heading_deg,
            captured_utc=file_mtime_utc(entry.path),
        )
        place_id = map_db.add_place(place, result)
    except DuplicatePlaceError as error:
        message = f"already in the map as place {error.place_id}"
        return Outcome(entry.image, Status.SKIPPED, error.place_id, message)
    except ValueError as error:
        return Outcome(entry.image, Status.FAILED, message=_error_text(error))
    counts = ", ".join(f"{f.detector} {f.n}" for f in result)
    return Outcome(entry.image, Status.ADDED, place_id, f"room {entry.room!r}, {counts}")

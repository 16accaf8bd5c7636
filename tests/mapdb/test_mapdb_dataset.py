"""Reading a dataset: manifest.csv (columns, optional pose, errors naming file, line and column)
or one sub-folder of panoramas per room; writing one that reads back the same."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from mapdb.dataset import (
    ManifestEntry,
    read_dataset,
    read_edges,
    read_manifest,
    read_room_folders,
    sha256_file,
    write_edges,
    write_manifest,
)
from mapdb.errors import ManifestError


def write_manifest_text(folder: Path, text: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "manifest.csv").write_text(text, encoding="utf-8")
    return folder


def test_manifest_rows_with_and_without_pose(tmp_path: Path) -> None:
    folder = write_manifest_text(
        tmp_path / "ds",
        "\ufeffimage,room,x_m,y_m,heading_deg,extra\n"
        "a.png,kitchen,1.5,-2,90,x\n"
        "sub/b.png, hall ,,,\n"
        "\n"
        "c.png,hall,0,0,\n",
    )
    a, b, c = read_manifest(folder)
    assert (a.image, a.room, a.x_m, a.y_m, a.heading_deg) == ("a.png", "kitchen", 1.5, -2.0, 90.0)
    assert a.path == folder / "a.png"
    assert (b.room, b.x_m, b.y_m, b.heading_deg) == ("hall", None, None, None)
    assert b.path == folder / "sub" / "b.png"
    assert (c.x_m, c.heading_deg) == (0.0, None)


def test_a_written_manifest_reads_back_the_same_rows(tmp_path: Path) -> None:
    folder = tmp_path / "ds"
    folder.mkdir()
    written = [
        ManifestEntry("images/a.png", folder / "images/a.png", "kitchen", 1.25, -0.1, 179.999999),
        ManifestEntry("images/b, c.png", folder / "images/b, c.png", "hall", None, None, None),
    ]
    manifest = write_manifest(folder, written)
    assert manifest.read_text().splitlines()[0] == "image,room,x_m,y_m,heading_deg"
    assert manifest.read_text().splitlines()[2] == '"images/b, c.png",hall,,,'
    read = read_manifest(folder)
    assert [(e.image, e.path, e.room, e.x_m, e.y_m, e.heading_deg) for e in read] == [
        (e.image, e.path, e.room, e.x_m, e.y_m, e.heading_deg) for e in written
    ]
    assert [e.line for e in read] == [2, 3]


def test_a_written_edges_file_reads_back(tmp_path: Path) -> None:
    write_edges(tmp_path, [("hall", "kitchen"), ("hall", "office")])
    assert read_edges(tmp_path) == [("hall", "kitchen"), ("hall", "office")]


@pytest.mark.parametrize(
    ("pose", "message"),
    [
        ((1.0, None, 0.0), "give both x_m and y_m or neither"),
        ((1.0, 2.0, float("inf")), "heading_deg must be a finite number"),
        ((float("nan"), 2.0, 0.0), "x_m must be a finite number"),
    ],
)
def test_an_entry_no_manifest_could_hold_is_refused(
    tmp_path: Path, pose: tuple[float | None, float | None, float | None], message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        ManifestEntry("a.png", tmp_path / "a.png", "hall", *pose)


def test_an_entry_needs_an_image_and_a_room_name(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="image must not be empty"):
        ManifestEntry(" ", tmp_path, "hall", None, None, None)
    with pytest.raises(ValueError, match=r"room name .* control character"):
        ManifestEntry("a.png", tmp_path / "a.png", "hall\nkitchen", None, None, None)


def test_missing_column_is_named(tmp_path: Path) -> None:
    folder = write_manifest_text(tmp_path / "ds", "image,room,x_m,heading_deg\na.png,hall,1,0\n")
    with pytest.raises(ManifestError, match=r"manifest\.csv lacks column\(s\) 'y_m'"):
        read_manifest(folder)


@pytest.mark.parametrize(
    ("row", "message"),
    [
        ("a.png,hall,one,2,3", r"line 2: column 'x_m' must be a number or empty, got 'one'"),
        ("a.png,hall,1,2,nan", r"line 2: column 'heading_deg' must be finite"),
        ("a.png,,1,2,3", r"line 2: column 'room' is empty"),
        (",hall,1,2,3", r"line 2: column 'image' is empty"),
        ("a.png,hall,1,,3", r"line 2: give both 'x_m' and 'y_m'"),
    ],
)
def test_bad_values_name_line_and_column(tmp_path: Path, row: str, message: str) -> None:
    folder = write_manifest_text(tmp_path / "ds", f"image,room,x_m,y_m,heading_deg\n{row}\n")
    with pytest.raises(ManifestError, match=message):
        read_manifest(folder)


def test_missing_manifest_and_folder_are_named(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    with pytest.raises(ManifestError, match=r"empty/manifest\.csv not found"):
        read_manifest(tmp_path / "empty")
    with pytest.raises(ManifestError, match=r"dataset folder .*nowhere does not exist"):
        read_manifest(tmp_path / "nowhere")


def write_files(folder: Path, *names: str) -> Path:
    for name in names:
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_bytes(b"not decoded here")
    return folder


def test_room_folders_give_one_entry_per_image_without_pose(tmp_path: Path) -> None:
    folder = write_files(
        tmp_path / "house",
        "kitchen/IMG_0002.JPG", "kitchen/IMG_0001.jpg", "hall/a.png", "hall/notes.txt",
        "hall/._a.png", ".thumbnails/x.jpg", "empty_room/readme.md",
    )  # fmt: skip
    entries = read_room_folders(folder)
    assert [(e.image, e.room) for e in entries] == [
        ("hall/a.png", "hall"),
        ("kitchen/IMG_0001.jpg", "kitchen"),
        ("kitchen/IMG_0002.JPG", "kitchen"),
    ]
    assert entries[0].path == folder / "hall" / "a.png"
    assert {(e.x_m, e.y_m, e.heading_deg, e.line) for e in entries} == {(None, None, None, 0)}


def test_read_dataset_prefers_the_manifest(tmp_path: Path) -> None:
    folder = write_files(tmp_path / "ds", "kitchen/a.jpg")
    assert [e.room for e in read_dataset(folder)] == ["kitchen"]
    write_manifest_text(folder, "image,room,x_m,y_m,heading_deg\nkitchen/a.jpg,pantry,1,2,0\n")
    assert [e.room for e in read_dataset(folder)] == ["pantry"]


def test_images_outside_room_folders_are_refused_naming_them(tmp_path: Path) -> None:
    folder = write_files(tmp_path / "ds", "kitchen/a.jpg", "b.jpg")
    with pytest.raises(ManifestError, match=r"holds images directly \(b\.jpg\): put each room"):
        read_dataset(folder)


def test_a_folder_without_manifest_or_room_images_says_what_a_dataset_is(tmp_path: Path) -> None:
    folder = write_files(tmp_path / "ds", "kitchen/notes.txt")
    with pytest.raises(ManifestError, match=r"no manifest\.csv and no room sub-folder with images"):
        read_dataset(folder)


def test_a_dataset_whose_manifest_is_gone_is_not_read_as_a_room_named_images(
    tmp_path: Path,
) -> None:
    folder = write_files(tmp_path / "ds", "images/pano_000.png")
    with pytest.raises(ManifestError, match=r"is the manifest missing"):
        read_dataset(folder)


def test_a_room_folder_whose_name_is_no_room_name_is_named(tmp_path: Path) -> None:
    folder = write_files(tmp_path / "ds", "bad\troom/a.jpg")
    with pytest.raises(ManifestError, match=r"bad\\troom.*control character"):
        read_room_folders(folder)


def test_a_room_image_linked_from_outside_is_refused_unless_allowed(tmp_path: Path) -> None:
    outside = write_files(tmp_path / "elsewhere", "a.jpg") / "a.jpg"
    folder = write_files(tmp_path / "ds", "kitchen/b.jpg")
    (folder / "kitchen" / "a.jpg").symlink_to(outside)
    with pytest.raises(ManifestError, match=r"image 'kitchen/a\.jpg' lies outside"):
        read_room_folders(folder)
    assert len(read_room_folders(folder, allow_outside=True)) == 2


def test_sha256_file_matches_hashlib(tmp_path: Path) -> None:
    path = tmp_path / "blob.bin"
    data = bytes(range(256)) * 5000
    path.write_bytes(data)
    assert sha256_file(path, chunk_bytes=1000) == hashlib.sha256(data).hexdigest()


def test_edges_csv_is_optional(tmp_path):
    assert read_edges(tmp_path) == []


def test_edges_csv_rows_are_room_pairs(tmp_path):
    (tmp_path / "edges.csv").write_text("room_a,room_b\nhall,office\nhall,kitchen\n")
    assert read_edges(tmp_path) == [("hall", "office"), ("hall", "kitchen")]


def test_an_edge_to_itself_names_the_file_and_line(tmp_path):
    (tmp_path / "edges.csv").write_text("room_a,room_b\nhall,hall\n")
    with pytest.raises(ManifestError, match=r"edges.csv line 2"):
        read_edges(tmp_path)


def test_an_edges_file_without_its_header_is_rejected(tmp_path):
    (tmp_path / "edges.csv").write_text("a,b\nhall,office\n")
    with pytest.raises(ManifestError, match="room_a,room_b"):
        read_edges(tmp_path)

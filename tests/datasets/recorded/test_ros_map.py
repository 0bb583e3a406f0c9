"""ROS map_server maps: the pixel rules of each mode, the row flip, round trips and every malformed-input error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from locbench.core.errors import DataNotFound
from locbench.datasets.dataset import OccupancyGrid
from locbench.datasets.recorded.files import RecordedDataError
from locbench.datasets.recorded.ros_map import load_map_server_map, read_pgm, save_map_server_map
from locbench.datasets.synthetic.scenarios import TinyCircleScenario

YAML = """image: {image}
resolution: 0.1
origin: [-1.0, 2.0, 0.0]
negate: {negate}
occupied_thresh: 0.65
free_thresh: 0.196
mode: {mode}
"""


def _write_map(
    folder: Path,
    pix: np.ndarray,
    *,
    negate: int = 0,
    mode: str = "trinary",
    maxval: int = 255,
    header: bytes | None = None,
) -> Path:
    """A hand-written P5 PGM (``pix`` row 0 = TOP of the image) and its YAML."""
    h, w = pix.shape
    data = pix.astype(">u2").tobytes() if maxval > 255 else pix.astype(np.uint8).tobytes()
    head = header if header is not None else f"P5\n# a comment\n{w} {h}\n{maxval}\n".encode()
    (folder / "m.pgm").write_bytes(head + data)
    y = folder / "m.yaml"
    y.write_text(YAML.format(image="m.pgm", negate=negate, mode=mode))
    return y


def test_trinary_pixels_and_row_flip(tmp_path: Path) -> None:
    # top image row: black (occupied), white (free), map_saver grey (unknown); bottom row all white
    pix = np.array([[0, 254, 205], [255, 255, 255]])
    g = load_map_server_map(_write_map(tmp_path, pix))
    assert g.shape == (2, 3)
    assert g.resolution == 0.1 and g.origin == (-1.0, 2.0, 0.0)
    # grid row 0 is the bottom of the map (y = origin_y): the image's last row
    np.testing.assert_array_equal(g.occupancy, [[0.0, 0.0, 0.0], [1.0, 0.0, -1.0]])
    # the world point in the top-left cell is occupied
    r, c = g.world_to_cell([-0.95, 2.15])
    assert (r, c) == (1, 0) and g.occupied()[r, c]


def test_negate_swaps_black_and_white(tmp_path: Path) -> None:
    pix = np.array([[0, 255]])
    g = load_map_server_map(_write_map(tmp_path, pix, negate=1))
    np.testing.assert_array_equal(g.occupancy, [[0.0, 1.0]])


def test_scale_mode_keeps_the_probability(tmp_path: Path) -> None:
    pix = np.array([[0, 128, 200, 255]])
    g = load_map_server_map(_write_map(tmp_path, pix, mode="scale"))
    np.testing.assert_allclose(g.occupancy[0], (255 - pix[0]) / 255.0)
    np.testing.assert_array_equal(g.occupied()[0], [True, False, False, False])
    np.testing.assert_array_equal(g.free()[0], [False, False, False, True])


def test_raw_mode_values(tmp_path: Path) -> None:
    g = load_map_server_map(_write_map(tmp_path, np.array([[0, 50, 100, 255]]), mode="raw"))
    np.testing.assert_array_equal(g.occupancy[0], [0.0, 0.5, 1.0, -1.0])
    with pytest.raises(RecordedDataError, match=r"m\.pgm: raw mode: pixel \(0, 1\) is 200, expected 0\.\.100"):
        load_map_server_map(_write_map(tmp_path, np.array([[0, 200]]), mode="raw"))


def test_sixteen_bit_pgm(tmp_path: Path) -> None:
    pix = np.array([[0, 65535, 40000]])
    g = load_map_server_map(_write_map(tmp_path, pix, maxval=65535))
    # p = (65535 - x) / 65535: 1 (occupied), 0 (free), 0.39 (unknown)
    np.testing.assert_array_equal(g.occupancy[0], [1.0, 0.0, -1.0])
    got, maxval = read_pgm(tmp_path / "m.pgm")
    assert maxval == 65535
    np.testing.assert_array_equal(got, pix)


@pytest.mark.parametrize("mode", ["trinary", "scale", "raw"])
def test_save_and_load_round_trip(tmp_path: Path, mode: str) -> None:
    rng = np.random.default_rng(3)
    occ = rng.choice([0.0, 0.1, 0.5, 0.9, 1.0, -1.0], size=(17, 23))
    if mode == "scale":
        occ[occ < 0] = 0.3  # a PGM in scale mode has no unknown cells
    grid = OccupancyGrid(occ, 0.05, (1.5, -2.25, 0.0), occupied_thresh=0.7, free_thresh=0.2)
    y = save_map_server_map(grid, tmp_path / "sub" / "office.yaml", mode=mode)
    assert sorted(p.name for p in y.parent.iterdir()) == ["office.pgm", "office.yaml"]  # nothing half-written
    g = load_map_server_map(y)
    assert g.shape == grid.shape and g.resolution == 0.05 and g.origin == (1.5, -2.25, 0.0)
    assert (g.occupied_thresh, g.free_thresh) == (0.7, 0.2)
    np.testing.assert_array_equal(g.occupied(), grid.occupied())
    np.testing.assert_array_equal(g.free(), grid.free())
    if mode == "raw":
        np.testing.assert_array_equal(g.occupancy, occ)
    if mode == "scale":
        np.testing.assert_allclose(g.occupancy, occ, atol=0.5 / 255 + 1e-12)


def test_round_trip_of_a_synthetic_world_grid(tmp_path: Path) -> None:
    grid = TinyCircleScenario().world().occupancy_grid()
    g = load_map_server_map(save_map_server_map(grid, tmp_path / "map.yaml"))
    np.testing.assert_array_equal(g.occupancy, grid.occupancy)
    assert g.origin == grid.origin and g.resolution == grid.resolution
    # saving again over the old files replaces them
    save_map_server_map(g, tmp_path / "map.yaml")
    np.testing.assert_array_equal(load_map_server_map(tmp_path / "map.yaml").occupancy, grid.occupancy)


def test_other_image_types_through_pillow(tmp_path: Path) -> None:
    image = pytest.importorskip("PIL.Image")
    pix = np.array([[0, 254, 205], [255, 255, 255]], dtype=np.uint8)
    image.fromarray(pix, mode="L").save(tmp_path / "m.png")
    (tmp_path / "m.yaml").write_text(YAML.format(image="m.png", negate=0, mode="trinary"))
    g = load_map_server_map(tmp_path / "m.yaml")
    np.testing.assert_array_equal(g.occupancy, [[0.0, 0.0, 0.0], [1.0, 0.0, -1.0]])


# --- malformed input -----------------------------------------------------------------------------


@pytest.mark.parametrize("field", ["image", "resolution", "origin"])
def test_missing_field(tmp_path: Path, field: str) -> None:
    y = _write_map(tmp_path, np.zeros((2, 2)))
    y.write_text("\n".join(line for line in y.read_text().splitlines() if not line.startswith(field + ":")))
    with pytest.raises(RecordedDataError, match=rf"m\.yaml: missing required field '{field}'"):
        load_map_server_map(y)


@pytest.mark.parametrize(
    ("line", "bad", "match"),
    [
        (2, "resolution: fine", r"m\.yaml:2: field 'resolution': expected a finite number, got 'fine'"),
        (2, "resolution: -0.1", r"m\.yaml:2: field 'resolution': expected 0.001 to 1.0 m per pixel"),
        (3, "origin: [1.0, 2.0]", r"m\.yaml:3: field 'origin': expected a list \[x, y, yaw\] of 3 numbers"),
        (3, "origin: [1.0, 2.0, 0.3]", r"m\.yaml:3: field 'origin': yaw is 0\.3 rad; expected 0"),
        (4, "negate: maybe", r"m\.yaml:4: field 'negate': expected 0, 1, true or false"),
        (5, "occupied_thresh: 0.1", r"m\.yaml:6: field 'free_thresh': expected 0 <= free_thresh <= occupied_thresh"),
        (7, "mode: fancy", r"m\.yaml:7: field 'mode': expected one of trinary, scale, raw, got 'fancy'"),
        (1, "image: [1, 2]", r"m\.yaml:1: field 'image': expected the image file name"),
    ],
)
def test_wrong_field_type_names_the_line(tmp_path: Path, line: int, bad: str, match: str) -> None:
    y = _write_map(tmp_path, np.zeros((2, 2)))
    lines = y.read_text().splitlines()
    lines[line - 1] = bad
    y.write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordedDataError, match=match):
        load_map_server_map(y)


def test_malformed_yaml_names_the_line(tmp_path: Path) -> None:
    y = tmp_path / "m.yaml"
    y.write_text("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0\nnegate: 0\n")
    with pytest.raises(RecordedDataError, match=r"m\.yaml:\d+: malformed YAML"):
        load_map_server_map(y)
    y.write_text("- just\n- a list\n")
    with pytest.raises(RecordedDataError, match=r"m\.yaml: expected a YAML mapping"):
        load_map_server_map(y)


def test_missing_files_are_errors_not_skips(tmp_path: Path) -> None:
    # a map is a path the user typed: its absence is an error, never a "data not found" skip
    with pytest.raises(RecordedDataError, match=r"nowhere\.yaml: missing map YAML file") as info:
        load_map_server_map(tmp_path / "nowhere.yaml")
    assert not isinstance(info.value, DataNotFound)
    y = _write_map(tmp_path, np.zeros((2, 2)))
    (tmp_path / "m.pgm").unlink()
    with pytest.raises(
        RecordedDataError, match=r"m\.pgm: map image not found \(field 'image' = 'm\.pgm' at .*m\.yaml:1\)"
    ) as info:
        load_map_server_map(y)
    assert not isinstance(info.value, DataNotFound)


@pytest.mark.parametrize(
    ("header", "match"),
    [
        (b"P6\n3 2\n255\n", r"m\.pgm:1: bad PGM header: magic is 'P6', expected 'P5'"),
        (b"P5\n# comment\nthree 2\n255\n", r"m\.pgm:3: bad PGM header: width is 'three', expected a positive integer"),
        (b"P5\n3 2\n", r"m\.pgm:3: bad PGM header: maxval is '\\x00.*', expected a positive integer"),
        (b"P5\n3 2\n70000\n", r"m\.pgm:3: bad PGM header: maxval 70000, expected 1\.\.65535"),
        (b"P5\n0 2\n255\n", r"m\.pgm:3: bad PGM header: size 0 x 2"),
    ],
)
def test_bad_pgm_header(tmp_path: Path, header: bytes, match: str) -> None:
    y = _write_map(tmp_path, np.zeros((2, 3)), header=header)
    with pytest.raises(RecordedDataError, match=match):
        load_map_server_map(y)


def test_header_cut_short(tmp_path: Path) -> None:
    (tmp_path / "m.pgm").write_bytes(b"P5\n3 2")
    with pytest.raises(RecordedDataError, match=r"m\.pgm:2: bad PGM header: missing maxval \(file ends"):
        read_pgm(tmp_path / "m.pgm")


def test_truncated_image_data(tmp_path: Path) -> None:
    y = _write_map(tmp_path, np.zeros((4, 5)))
    (tmp_path / "m.pgm").write_bytes((tmp_path / "m.pgm").read_bytes()[:-3])
    msg = r"m\.pgm: truncated image data: 17 bytes after the header, expected 20"
    with pytest.raises(RecordedDataError, match=msg):
        load_map_server_map(y)
    y16 = _write_map(tmp_path, np.zeros((2, 2)), maxval=1000)
    (tmp_path / "m.pgm").write_bytes((tmp_path / "m.pgm").read_bytes()[:-1])
    with pytest.raises(RecordedDataError, match=r"truncated image data: 7 bytes after the header, expected 8"):
        load_map_server_map(y16)


def test_pixel_above_maxval(tmp_path: Path) -> None:
    y = _write_map(tmp_path, np.array([[0, 200]]), header=b"P5\n2 1\n100\n")
    with pytest.raises(RecordedDataError, match=r"pixel \(0, 1\) is 200, above the header's maxval 100"):
        load_map_server_map(y)


def test_save_rejects_what_the_format_cannot_hold(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="yaw must be 0"):
        save_map_server_map(OccupancyGrid(np.zeros((2, 2)), 0.1, (0.0, 0.0, 0.5)), tmp_path / "a.yaml")
    with pytest.raises(ValueError, match="scale mode cannot store unknown cells"):
        save_map_server_map(OccupancyGrid(-np.ones((2, 2)), 0.1), tmp_path / "a.yaml", mode="scale")
    assert not list(tmp_path.iterdir())

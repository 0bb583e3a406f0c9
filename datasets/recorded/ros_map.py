"""ROS map_server maps (a YAML file naming a PGM image) as :class:`~locbench.datasets.dataset.OccupancyGrid`.

Format (ROS ``map_server`` / nav2 ``map_server``, http://wiki.ros.org/map_server#Map_format): a YAML file

.. code-block:: yaml

    image: office.pgm          # relative to the YAML file's folder, or absolute
    resolution: 0.05           # m per pixel
    origin: [-10.0, -5.0, 0.0] # world pose (x m, y m, yaw rad) of the LOWER-LEFT pixel
    negate: 0                  # 1 swaps the white = free / black = occupied semantics
    occupied_thresh: 0.65
    free_thresh: 0.196
    mode: trinary              # optional: trinary (default), scale or raw

and the image. Pixel value ``x`` in [0, maxval] becomes the occupancy probability ``p = (maxval - x) / maxval``
(``p = x / maxval`` when ``negate`` is set), then:

- ``trinary``: ``p > occupied_thresh`` -> occupied (1.0 here), ``p < free_thresh`` -> free (0.0), else unknown (-1);
- ``scale``: the same two classes; between the thresholds map_server sends a graded value. Here the probability
  ``p`` itself is kept (it is what the thresholds of :class:`OccupancyGrid` compare against, so occupied and free
  cells are exactly map_server's); a PGM has no alpha channel, so no cell is unknown;
- ``raw``: the pixel value is the message value: 0..100 -> ``x / 100``, 255 -> unknown; anything else is an error.

Frames: the image's first row is the TOP of the map; :class:`OccupancyGrid` has row 0 at the bottom
(y = origin_y), so rows are flipped. A non-zero yaw in ``origin`` is an error (the grid is axis-aligned in the
world frame). Images: binary PGM (P5, 8 or 16 bit big-endian, ``#`` comments in the header) by a small parser of
our own; any other image type (PNG ...) through Pillow when it is installed, averaged to grey.

The YAML is read with ``yaml.safe_load`` semantics (no arbitrary objects) except that a key given twice in one
mapping is an error (``safe_load`` keeps the last value); a PGM must hold exactly the bytes its header announces
(fewer: cut; more: trailing bytes, a header that understates the image). Errors are
:class:`~locbench.datasets.recorded.files.RecordedDataError` naming the file, the line of the field (YAML) or the
header line / byte count (PGM) and what was expected.

Limits, checked before anything large is allocated: the YAML file is at most :data:`MAX_YAML_BYTES` and may
hold no alias (``*name``; a map_server file needs none, and nested aliases expand a few hundred bytes into
gigabytes); ``resolution`` lies in [:data:`MIN_RESOLUTION_M`, :data:`MAX_RESOLUTION_M`] m; ``origin`` within
:data:`~locbench.datasets.recorded.files.MAX_POSITION_M`; the image has at most ``max_cells`` pixels (default
:data:`~locbench.datasets.recorded.files.MAX_GRID_CELLS`, read from the PGM header or the image header before
its pixels are decoded; Pillow's own decompression-bomb guard stays on); and the map spans at most
:data:`MAX_EXTENT_M` per side.

The loaders of a user's recording (:mod:`~locbench.datasets.recorded.rosbag`,
:mod:`~locbench.datasets.recorded.textlog`) read their map through :func:`load_map_and_lines`: once per file
version, with the line segments of :func:`~locbench.datasets.recorded.scan_map.extract_map_lines` when asked.
"""

from __future__ import annotations

import functools
import math
import os
import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
import yaml

from locbench.core.errors import ConfigError
from locbench.datasets.dataset import LineMap, OccupancyGrid
from locbench.datasets.recorded.files import (
    MAX_GRID_CELLS,
    MAX_POSITION_M,
    RecordedDataError,
    check_cells,
    quote,
)

FloatArray = npt.NDArray[np.float64]
MapMode = Literal["trinary", "scale", "raw"]
MAP_MODES: tuple[str, ...] = ("trinary", "scale", "raw")

#: Pixel values map_saver writes in trinary mode (negate = 0): occupied, free, unknown.
_PIX_OCCUPIED, _PIX_FREE, _PIX_UNKNOWN = 0, 254, 205
#: Raw-mode pixel value of an unknown cell (-1 as an unsigned byte).
_RAW_UNKNOWN = 255
#: Largest map YAML file, bytes (a map_server file is a few hundred).
MAX_YAML_BYTES = 65536
#: Bounds of ``resolution``, m per pixel (map_server maps use 0.01 to 0.2).
MIN_RESOLUTION_M = 0.001
MAX_RESOLUTION_M = 1.0
#: Largest side of a map, m (a campus is a few hundred metres; the scan database and ray casts scale with it).
MAX_EXTENT_M = 2000.0


# --- YAML ----------------------------------------------------------------------------------------


def _key_lines(path: Path, text: str) -> dict[str, int]:
    """1-based line of each top-level key of a YAML mapping (for messages)."""
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError:
        return {}
    if not isinstance(node, yaml.MappingNode):
        return {}
    return {str(k.value): int(k.start_mark.line) + 1 for k, _ in node.value if isinstance(k, yaml.ScalarNode)}


def _refuse_aliases(path: Path, text: str) -> None:
    """Raise at the first YAML alias (``*name``): a map needs none, and nested ones expand without bound."""
    try:
        for event in yaml.parse(text, Loader=yaml.SafeLoader):
            if isinstance(event, yaml.AliasEvent):
                line = int(event.start_mark.line) + 1 if event.start_mark is not None else None
                raise RecordedDataError(
                    path,
                    f"YAML alias *{quote(event.anchor, 60)}: expected plain values (a map_server file uses no "
                    "anchors or aliases)",
                    line,
                )
    except yaml.YAMLError:
        return  # reported with its line by safe_load below


def _refuse_duplicate_keys(path: Path, text: str) -> None:
    """Raise at the second occurrence of a key in any YAML mapping (``safe_load`` would let the last one win)."""
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError:
        return  # reported with its line by safe_load below
    stack = [root] if root is not None else []
    while stack:
        node = stack.pop()
        if isinstance(node, yaml.MappingNode):
            seen: dict[str, int] = {}
            for key, value in node.value:
                if isinstance(key, yaml.ScalarNode):
                    line = int(key.start_mark.line) + 1
                    if key.value in seen:
                        raise RecordedDataError(
                            path,
                            f"duplicate key {quote(key.value, 60)} (first on line {seen[key.value]}): expected each "
                            "key once (the last value would silently win)",
                            line,
                        )
                    seen[key.value] = line
                stack.append(value)
        elif isinstance(node, yaml.SequenceNode):
            stack.extend(node.value)


def _read_yaml(path: Path) -> tuple[dict[str, Any], dict[str, int]]:
    try:
        size = path.stat().st_size
        if size > MAX_YAML_BYTES:
            raise RecordedDataError(path, f"{size} bytes, expected a map_server YAML file of at most {MAX_YAML_BYTES}")
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise RecordedDataError(path, "missing map YAML file") from None
    except UnicodeDecodeError as exc:
        raise RecordedDataError(path, f"not UTF-8 text ({exc.reason}); expected a map_server YAML file") from None
    _refuse_aliases(path, text)
    _refuse_duplicate_keys(path, text)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = int(mark.line) + 1 if mark is not None else None
        problem = getattr(exc, "problem", None) or str(exc)
        raise RecordedDataError(path, f"malformed YAML: {quote(problem)}", line) from None
    if not isinstance(data, dict):
        raise RecordedDataError(path, f"expected a YAML mapping with map_server fields, got {type(data).__name__}")
    return data, _key_lines(path, text)


class _Fields:
    """Typed access to the YAML mapping with errors naming the field and its line."""

    def __init__(self, path: Path, data: dict[str, Any], lines: dict[str, int]) -> None:
        self.path, self.data, self.lines = path, data, lines

    def fail(self, key: str, message: str) -> RecordedDataError:
        return RecordedDataError(self.path, f"field {key!r}: {message}", self.lines.get(key))

    def required(self, key: str) -> Any:
        if key not in self.data:
            raise RecordedDataError(self.path, f"missing required field {key!r} (map_server YAML)")
        return self.data[key]

    def number(self, key: str, default: float | None = None) -> float:
        v = self.required(key) if default is None or key in self.data else default
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
            raise self.fail(key, f"expected a finite number, got {quote(v)}")
        return float(v)

    def flag(self, key: str, default: bool) -> bool:
        v = self.data.get(key, default)
        if isinstance(v, bool):
            return v
        if isinstance(v, int) and v in (0, 1):
            return bool(v)
        raise self.fail(key, f"expected 0, 1, true or false, got {quote(v)}")


def _origin(f: _Fields) -> tuple[float, float, float]:
    v = f.required("origin")
    if not isinstance(v, list) or len(v) != 3:
        raise f.fail("origin", f"expected a list [x, y, yaw] of 3 numbers, got {quote(v)}")
    out = []
    for item in v:
        if isinstance(item, bool) or not isinstance(item, (int, float)) or not math.isfinite(float(item)):
            raise f.fail("origin", f"expected a list [x, y, yaw] of 3 finite numbers, got {quote(v)}")
        out.append(float(item))
    if out[2] != 0.0:
        raise f.fail(
            "origin", f"yaw is {out[2]!r} rad; expected 0 (locbench grids are axis-aligned: rotate the map image)"
        )
    if max(abs(out[0]), abs(out[1])) > MAX_POSITION_M:
        raise f.fail("origin", f"x, y = {out[0]!r}, {out[1]!r} m, expected within +-{MAX_POSITION_M} m")
    return (out[0], out[1], 0.0)


# --- images --------------------------------------------------------------------------------------


def read_pgm(path: str | os.PathLike[str], max_cells: int = MAX_GRID_CELLS) -> tuple[npt.NDArray[np.uint16], int]:
    """Read a binary PGM (P5) image.

    Parameters
    ----------
    path : path-like
        The file.
    max_cells : int
        Largest image read, pixels (refused from the header, before the pixels are converted).

    Returns
    -------
    pixels : ndarray of int64, shape (height, width)
        Grey values, first row at the TOP of the image (as stored).
    maxval : int
        The header's maximum value (255 for 8-bit, up to 65535 for 16-bit big-endian samples).

    Raises
    ------
    RecordedDataError
        A missing file, a bad header (naming the header line and the token that is wrong) or data cut short.
    """
    # long: the header's fields read in order, each with its own refusal; the numpydoc is a third of it
    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise RecordedDataError(p, "missing map image") from None
    if raw[:2] != b"P5":
        what = raw[:2].decode("latin-1") if raw else "an empty file"
        raise RecordedDataError(p, f"bad PGM header: magic is {what!r}, expected 'P5' (binary greymap)", 1)
    pos, line = 2, 1
    values: list[int] = []
    names = ("width", "height", "maxval")
    while len(values) < 3:
        # whitespace and comments between header tokens
        while pos < len(raw) and raw[pos : pos + 1] in (b" ", b"\t", b"\r", b"\n", b"#"):
            if raw[pos : pos + 1] == b"#":
                end = raw.find(b"\n", pos)
                pos = len(raw) if end < 0 else end
                continue
            if raw[pos : pos + 1] == b"\n":
                line += 1
            pos += 1
        start = pos
        while pos < len(raw) and raw[pos : pos + 1] not in (b" ", b"\t", b"\r", b"\n", b"#"):
            pos += 1
        token = raw[start:pos]
        name = names[len(values)]
        if not token:
            raise RecordedDataError(p, f"bad PGM header: missing {name} (file ends in the header)", line)
        if not token.isdigit():
            raise RecordedDataError(
                p, f"bad PGM header: {name} is {token.decode('latin-1')!r}, expected a positive integer", line
            )
        values.append(int(token))
    width, height, maxval = values
    if width < 1 or height < 1:
        raise RecordedDataError(p, f"bad PGM header: size {width} x {height}, expected positive", line)
    if not 0 < maxval < 65536:
        raise RecordedDataError(p, f"bad PGM header: maxval {maxval}, expected 1..65535", line)
    check_cells(p, height, width, max_cells, "the map's max_cells limits the image's pixels")
    if pos >= len(raw) or raw[pos : pos + 1] not in (b" ", b"\t", b"\r", b"\n"):
        raise RecordedDataError(p, "bad PGM header: expected one whitespace byte before the pixel data", line)
    pos += 1  # exactly one whitespace byte separates the header from the data
    nbytes = 1 if maxval < 256 else 2
    need = width * height * nbytes
    have = len(raw) - pos
    if have < need:
        raise RecordedDataError(
            p, f"truncated image data: {have} bytes after the header, expected {need} ({width} x {height} x {nbytes})"
        )
    if have > need:
        # a header that understates the image (or two images in one file) would silently read a part of it
        raise RecordedDataError(
            p,
            f"{have - need} trailing bytes: {have} bytes after the header, expected exactly {need} "
            f"({width} x {height} x {nbytes}) as the header says",
        )
    dtype = np.dtype(np.uint8) if nbytes == 1 else np.dtype(">u2")
    # uint16 holds every 8- and 16-bit sample exactly in a quarter of int64's memory (a 2^24-pixel map: 34 MB)
    pix = np.frombuffer(raw, dtype=dtype, count=width * height, offset=pos).reshape(height, width).astype(np.uint16)
    if int(pix.max()) > maxval:
        r, c = np.unravel_index(int(np.argmax(pix)), pix.shape)
        raise RecordedDataError(p, f"pixel ({r}, {c}) is {int(pix[r, c])}, above the header's maxval {maxval}")
    return pix, maxval


def _read_other_image(
    path: Path, max_cells: int = MAX_GRID_CELLS
) -> tuple[npt.NDArray[np.uint16], int, npt.NDArray[np.bool_] | None]:
    """Any Pillow-readable image as grey values 0..255 (channels averaged) and a transparency mask.

    The size is read from the header and refused above ``max_cells`` before the pixels are decoded; Pillow's
    decompression-bomb guard (``Image.MAX_IMAGE_PIXELS``) stays on.
    """
    try:
        from PIL import Image
    except ImportError:
        raise RecordedDataError(
            path, "not a PGM image, and Pillow (needed for other image types) is not installed: pip install pillow"
        ) from None
    if not path.is_file():
        raise RecordedDataError(path, "missing map image")
    try:
        with warnings.catch_warnings():
            # Pillow's guard warns between MAX_IMAGE_PIXELS and twice that: refuse there too, not just warn
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            im = Image.open(path)
        with im:
            width, height = im.size
            check_cells(path, height, width, max_cells, "the map's max_cells limits the image's pixels")
            im.load()
            rgba = np.asarray(im.convert("RGBA"), dtype=np.uint8)
            has_alpha = "A" in im.getbands() or "transparency" in im.info
    except RecordedDataError:
        raise
    except Exception as exc:  # Pillow raises many types for unreadable files (its bomb guard among them)
        raise RecordedDataError(path, f"unreadable image ({type(exc).__name__}: {quote(str(exc))})") from None
    mean = rgba[..., :3].sum(axis=-1, dtype=np.uint16) / 3.0
    np.rint(mean, out=mean)  # in place: one float64 temporary, not two
    grey = mean.astype(np.uint16)
    del mean
    transparent = rgba[..., 3] < 255 if has_alpha else None
    return grey, 255, transparent


# --- loading -------------------------------------------------------------------------------------


def load_map_server_map(yaml_path: str | os.PathLike[str], max_cells: int = MAX_GRID_CELLS) -> OccupancyGrid:
    """Read a ROS map_server map (YAML + image) as an occupancy grid.

    Parameters
    ----------
    yaml_path : path-like
        The map's YAML file; its ``image`` is relative to the YAML file's folder unless absolute.
    max_cells : int
        Largest map, cells (pixels); a larger image is refused before its pixels are decoded.

    Returns
    -------
    OccupancyGrid
        Occupancy in [0, 1] (-1 unknown) with row 0 at the bottom (y = origin y), ``resolution`` in m, ``origin``
        (x m, y m, 0), and the file's thresholds. See the module docstring for the mode semantics.

    Raises
    ------
    RecordedDataError
        A missing file, a missing field, a field of the wrong type (naming its line), a non-zero yaw, an image that
        is missing or malformed.
    """
    path = Path(yaml_path)
    data, lines = _read_yaml(path)
    f = _Fields(path, data, lines)
    image = f.required("image")
    if not isinstance(image, str) or not image.strip():
        raise f.fail("image", f"expected the image file name, got {image!r}")
    resolution = f.number("resolution")
    if not MIN_RESOLUTION_M <= resolution <= MAX_RESOLUTION_M:
        raise f.fail("resolution", f"expected {MIN_RESOLUTION_M} to {MAX_RESOLUTION_M} m per pixel, got {resolution!r}")
    origin = _origin(f)
    negate = f.flag("negate", False)
    occ_th = f.number("occupied_thresh", 0.65)
    free_th = f.number("free_thresh", 0.196)
    if not 0.0 <= free_th <= occ_th <= 1.0:
        raise f.fail(
            "free_thresh" if "free_thresh" in data else "occupied_thresh",
            f"expected 0 <= free_thresh <= occupied_thresh <= 1, got free {free_th!r}, occupied {occ_th!r}",
        )
    mode = data.get("mode", "trinary")
    if mode not in MAP_MODES:
        raise f.fail("mode", f"expected one of {', '.join(MAP_MODES)}, got {mode!r}")
    img_path = Path(image).expanduser()
    if not img_path.is_absolute():
        img_path = path.parent / img_path
    if not img_path.is_file():
        raise RecordedDataError(
            img_path, f"map image not found (field 'image' = {image!r} at {path}:{lines.get('image', '?')})"
        )
    transparent: npt.NDArray[np.bool_] | None = None
    with open(img_path, "rb") as fh:
        magic = fh.read(2)
    if magic == b"P5" or img_path.suffix.lower() == ".pgm":
        pix, maxval = read_pgm(img_path, max_cells)
    else:
        pix, maxval, transparent = _read_other_image(img_path, max_cells)
    side = max(pix.shape) * resolution
    if side > MAX_EXTENT_M:
        raise f.fail(
            "resolution",
            f"{pix.shape[1]} x {pix.shape[0]} pixels at {resolution!r} m span {side:.4g} m, expected at most "
            f"{MAX_EXTENT_M} m per side",
        )
    # image top row -> grid's last row: the pixels are flipped (a view), so the occupancy is built in grid order
    # without a flipped copy of it
    flipped = None if transparent is None else transparent[::-1]
    occupancy = _pixels_to_occupancy(img_path, pix[::-1], maxval, negate, occ_th, free_th, mode, flipped)
    return OccupancyGrid(
        occupancy=np.ascontiguousarray(occupancy),
        resolution=resolution,
        origin=origin,
        occupied_thresh=occ_th,
        free_thresh=free_th,
    )


def _pixels_to_occupancy(
    img_path: Path,
    pix: npt.NDArray[np.uint16],
    maxval: int,
    negate: bool,
    occ_th: float,
    free_th: float,
    mode: str,
    transparent: npt.NDArray[np.bool_] | None,
) -> FloatArray:
    """Occupancy from grey values by map_server's rules (module docstring), in the row order of ``pix`` (the image
    flipped to grid order by the caller; messages name the image's own rows)."""
    if mode == "raw":
        known = pix <= 100
        unknown = pix == _RAW_UNKNOWN
        bad = ~(known | unknown)
        if np.any(bad):
            r, c = (int(i) for i in np.argwhere(bad[::-1])[0])  # the first bad pixel in image order
            raise RecordedDataError(
                img_path,
                f"raw mode: pixel ({r}, {c}) is {int(pix[::-1][r, c])}, expected 0..100 or {_RAW_UNKNOWN} (unknown)",
            )
        return np.where(known, pix / 100.0, -1.0)
    # exact integers in float64 either way: the same probabilities as from int64 pixels
    p = pix / float(maxval) if negate else (maxval - pix) / float(maxval)  # pix <= maxval: no wrap-around
    if mode != "trinary":
        # scale keeps the probability itself; only transparency marks unknown there
        if transparent is not None:
            p[transparent] = -1.0
        return p
    out = np.full(p.shape, -1.0)
    out[p < free_th] = 0.0
    out[p > occ_th] = 1.0  # free_th <= occ_th: no cell is both
    return out


def load_map_and_lines(yaml_path: Path, with_lines: bool) -> tuple[OccupancyGrid, LineMap | None]:
    """A map_server map and, with ``with_lines``, the line segments along its occupied cells, read once per file
    version (the loaders of a user's recording read the map of every seed's dataset through this).

    Parameters
    ----------
    yaml_path : Path
        The map's YAML file (:func:`load_map_server_map`).
    with_lines : bool
        Also extract the map lines (:func:`~locbench.datasets.recorded.scan_map.extract_map_lines`).

    Returns
    -------
    OccupancyGrid
        The map, read-only.
    LineMap or None
        Its lines (read-only), or None without ``with_lines``.

    Raises
    ------
    RecordedDataError
        As :func:`load_map_server_map`; and a map with too many occupied cells for the line extraction, naming the
        ``map_lines`` option that skips it.
    """
    st = yaml_path.stat()
    return _map_cached(str(yaml_path.resolve()), st.st_size, st.st_mtime_ns, with_lines)


@functools.lru_cache(maxsize=4)
def _map_cached(path: str, size: int, mtime_ns: int, with_lines: bool) -> tuple[OccupancyGrid, LineMap | None]:
    """The map (and its lines) of a map_server YAML, cached per file version (a re-saved map is read again)."""
    del size, mtime_ns  # cache key only
    grid = load_map_server_map(path)
    grid.occupancy.setflags(write=False)
    if not with_lines:
        return grid, None
    # imported here: the line extraction's module compiles a kernel (numba), which reading a map needs not
    from locbench.datasets.recorded.scan_map import extract_map_lines

    try:
        lines, _ = extract_map_lines(grid)
    except ConfigError as exc:
        raise RecordedDataError(path, f"{exc}; give map_lines=false to skip the line map") from None
    lines.segments.setflags(write=False)
    return grid, lines


# --- saving --------------------------------------------------------------------------------------


def save_map_server_map(
    grid: OccupancyGrid,
    yaml_path: str | os.PathLike[str],
    *,
    mode: MapMode = "trinary",
    image_name: str | None = None,
) -> Path:
    """Write ``grid`` as a map_server map: an 8-bit P5 PGM beside a YAML file (both written atomically).

    Parameters
    ----------
    grid : OccupancyGrid
        The grid; its origin's yaw must be 0.
    yaml_path : path-like
        The YAML file to write; the image goes into the same folder.
    mode : {"trinary", "scale", "raw"}
        ``trinary``: occupied -> 0, free -> 254, anything else -> 205 (map_saver's values; others where the
        grid's thresholds would read these back as another class);
        ``scale``: ``x = round(255 (1 - p))`` (unknown cells cannot be written: error);
        ``raw``: ``x = round(100 p)``, unknown -> 255.
    image_name : str or None
        The image's file name; default: the YAML file's stem + ``.pgm``.

    Returns
    -------
    Path
        The YAML file.
    """
    if mode not in MAP_MODES:
        raise ValueError(f"mode must be one of {', '.join(MAP_MODES)}, got {mode!r}")
    if grid.origin[2] != 0.0:
        raise ValueError(f"grid origin yaw must be 0, got {grid.origin[2]!r}")
    ypath = Path(yaml_path)
    name = image_name or (ypath.stem + ".pgm")
    occ = np.asarray(grid.occupancy, dtype=np.float64)[::-1]  # grid row 0 (bottom) -> last image row
    unknown = occ < 0.0
    pix: npt.NDArray[np.uint8]
    if mode == "trinary":
        occupied_px, free_px, unknown_px = _trinary_pixels(float(grid.occupied_thresh), float(grid.free_thresh))
        pix = np.full(occ.shape, unknown_px, dtype=np.uint8)
        pix[grid.occupied()[::-1]] = occupied_px
        pix[grid.free()[::-1]] = free_px
    elif mode == "scale":
        if np.any(unknown):
            raise ValueError("scale mode cannot store unknown cells in a PGM (no alpha channel); use trinary or raw")
        pix = np.rint(255.0 * (1.0 - np.clip(occ, 0.0, 1.0))).astype(np.uint8)
    else:
        pix = np.where(unknown, _RAW_UNKNOWN, np.rint(100.0 * np.clip(occ, 0.0, 1.0))).astype(np.uint8)
    h, w = int(pix.shape[0]), int(pix.shape[1])
    header = f"P5\n# written by locbench\n{w} {h}\n255\n".encode("ascii")
    ox, oy = (float(v) for v in grid.origin[:2])
    doc = (
        f"image: {name}\n"
        f"resolution: {float(grid.resolution)!r}\n"
        f"origin: [{ox!r}, {oy!r}, 0.0]\n"
        f"negate: 0\n"
        f"occupied_thresh: {float(grid.occupied_thresh)!r}\n"
        f"free_thresh: {float(grid.free_thresh)!r}\n"
        f"mode: {mode}\n"
    )
    ypath.parent.mkdir(parents=True, exist_ok=True)
    _atomic_write_bytes(ypath.parent / name, lambda fh: (fh.write(header), fh.write(pix.tobytes())))
    _atomic_write_bytes(ypath, lambda fh: fh.write(doc.encode("utf-8")))
    return ypath


def _trinary_pixels(occ_th: float, free_th: float) -> tuple[int, int, int]:
    """Pixel values (occupied, free, unknown) that read back as their class under these thresholds.

    map_saver's 0 / 254 / 205 where they do (the default thresholds), else the nearest values that do.
    """

    def cls(x: int) -> str:
        p = (255 - x) / 255.0
        return "occupied" if p > occ_th else ("free" if p < free_th else "unknown")

    occupied = next((x for x in (_PIX_OCCUPIED, *range(1, 256)) if cls(x) == "occupied"), None)
    free = next((x for x in (_PIX_FREE, 255, *range(253, -1, -1)) if cls(x) == "free"), None)
    mid = round(255.0 * (1.0 - 0.5 * (occ_th + free_th)))
    unknown = next((x for x in (_PIX_UNKNOWN, mid, *range(256)) if cls(x) == "unknown"), None)
    if occupied is None or free is None or unknown is None:
        raise ValueError(
            f"thresholds occupied {occ_th!r} / free {free_th!r} leave no 8-bit pixel value for every class; "
            "use mode='raw'"
        )
    return occupied, free, unknown


def _atomic_write_bytes(path: Path, write: Callable[[Any], object]) -> None:
    """Write through a temporary file in the same folder, then rename over ``path``."""
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=path.suffix, dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)

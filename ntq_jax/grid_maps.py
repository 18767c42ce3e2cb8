"""Users' occupancy grids: ROS ``map_server`` maps and MovingAI ``.map`` files, as boxes.

Two standard formats are read into an :class:`OccupancyGrid` (a bool array,
its cell size and the world position of its lower-left corner):

* **ROS map_server**: a YAML file (``image``, ``resolution``, ``origin``,
  ``occupied_thresh``, ``free_thresh``, ``negate``; ``mode`` if given must be
  ``trinary``) and the image it names, a PGM (P2/P5, 8 or 16 bit) or a PNG,
  relative to the YAML. map_server's trinary rule: a pixel's lightness ``v``
  (the mean of its colour channels, alpha ignored; ``255 - v`` when ``negate``)
  gives ``p = (255 - v) / 255``; ``p > occupied_thresh`` is occupied,
  ``p < free_thresh`` free, anything else *unknown*. Unknown cells are
  occupied unless ``unknown="free"``. ``origin = [x, y, yaw]`` is the world
  position of the image's lower-left pixel corner (the image's first row is the
  map's top row); only ``yaw = 0`` is supported (the boxes are axis-aligned).
* **MovingAI** (``type octile``, ``height``, ``width``, ``map``, then ``height``
  rows of ``width`` characters): ``.``, ``G`` and ``S`` are passable, every
  other character (``@ O T W``) blocked. One cell is ``scale`` world units
  (default 1); the file's first row is the map's top row; the lower-left corner
  is at ``(0, 0)``.

Both readers accept CRLF line ends; a malformed file is one :class:`GridMapError`
line naming the file and the line or field.

:func:`rectangle_cover` turns the occupied cells into boxes (a deterministic,
exact cover: no free cell covered, every occupied cell covered, rectangles
disjoint), and :func:`grid_world` into a :class:`ntq_jax.geometry.World` whose
bounds are the grid's extent. A grid's cell ``(i, j)`` (row ``i`` counted from
the bottom, column ``j`` from the left) is the closed square
``[x0 + j r, x0 + (j + 1) r] x [y0 + i r, y0 + (i + 1) r]``: the same
convention as :func:`ntq_jax.geometry.rasterize`, so rasterising the imported
world at the grid's own resolution gives the grid back.

Coordinates: a world holds its bounds and boxes in float32 world coordinates.
:func:`grid_world` refuses (:class:`GridMapError`) a grid whose extent float32
cannot hold (an infinite or zero-width map, e.g. ``resolution: 1e300``) or
whose cell edges float32 would move by more than :data:`MAX_EDGE_ERROR` of a
cell, as a geo-referenced origin far from 0 does (``origin: [500000, 4000000,
0]`` at 5 cm cells: float32's spacing there is 3 cm). Such a map is planned
in its own frame: set its origin to ``[0, 0, 0]`` and add the origin to the
planned paths.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import yaml

from ntq_jax import artifacts, validation

UNKNOWN_POLICIES = ("occupied", "free")
#: the largest move of a cell edge by float32 rounding that an import accepts, in cells
MAX_EDGE_ERROR = 0.01
MOVINGAI_PASSABLE = ".GS"


class GridMapError(ValueError):
    """A malformed or unreadable grid map file (one line naming the file and the line or field)."""


@dataclasses.dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """An occupancy grid in world units.

    Attributes:
        occupied: ``(H, W)`` bool, row 0 at the bottom (``y = origin[1]``).
        resolution: the side of a cell in world units (> 0).
        origin: ``(x0, y0)``, the world position of the lower-left corner.
        source: the file it was read from (for messages), or ``""``.
    """

    occupied: np.ndarray
    resolution: float
    origin: tuple[float, float] = (0.0, 0.0)
    source: str = ""

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.occupied.shape)

    @property
    def bounds(self) -> list[list[float]]:
        """``[[xmin, xmax], [ymin, ymax]]`` of the grid's extent."""
        h, w = self.occupied.shape
        x0, y0 = self.origin
        return [[x0, x0 + w * self.resolution], [y0, y0 + h * self.resolution]]


# ---------------------------------------------------------------------------
# Rectangle cover
# ---------------------------------------------------------------------------


def rectangle_cover(occupied: np.ndarray) -> np.ndarray:
    """Disjoint rectangles whose union is exactly the occupied cells, ``(R, 4)`` int64 rows
    ``[row0, col0, row1, col1]`` (half-open: rows ``row0..row1-1``, columns ``col0..col1-1``).

    Deterministic greedy cover: every row is split into maximal runs of
    occupied cells; a run whose columns equal those of a rectangle ending on the
    row below extends that rectangle upwards, any other run starts a new one.
    Walls, corridors and blocks therefore become one box each. Linear in the
    number of cells.
    """
    occ = np.asarray(occupied, bool)
    if occ.ndim != 2:
        raise ValueError(f"occupied must be a 2-D array, got shape {occ.shape}")
    h, w = occ.shape
    open_rects: dict[tuple[int, int], int] = {}  # (col0, col1) -> row0 of the open rectangle
    out: list[tuple[int, int, int, int]] = []
    pad = np.zeros(w + 2, np.int8)
    for i in range(h):
        pad[1:-1] = occ[i]
        edges = np.flatnonzero(np.diff(pad))
        runs = set(zip(edges[0::2].tolist(), edges[1::2].tolist()))
        for span in [s for s in open_rects if s not in runs]:
            out.append((open_rects.pop(span), span[0], i, span[1]))
        for span in sorted(runs):
            open_rects.setdefault(span, i)
    for span, r0 in open_rects.items():
        out.append((r0, span[0], h, span[1]))
    out.sort()
    return np.asarray(out, np.int64).reshape(-1, 4)


def cover_boxes(grid: OccupancyGrid) -> np.ndarray:
    """The grid's :func:`rectangle_cover` as world boxes ``(R, 4)`` ``[cx, cy, half_w, half_h]``."""
    rects = rectangle_cover(grid.occupied).astype(np.float64)
    r, (x0, y0) = grid.resolution, grid.origin
    r0, c0, r1, c1 = rects.T
    return np.stack(
        [
            x0 + 0.5 * (c0 + c1) * r,
            y0 + 0.5 * (r0 + r1) * r,
            0.5 * (c1 - c0) * r,
            0.5 * (r1 - r0) * r,
        ],
        axis=1,
    )


def grid_world(grid: OccupancyGrid):
    """The grid as a :class:`ntq_jax.geometry.World`: its extent and the boxes of its cover.

    Raises:
        GridMapError: float32 cannot hold the grid's geometry (:func:`check_float32`).
    """
    from ntq_jax.geometry import World

    boxes = cover_boxes(grid)
    check_float32(grid, boxes)
    return World.create(grid.bounds, boxes)


def _edges(bounds: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    c, h = boxes[:, :2], boxes[:, 2:]
    return np.concatenate([bounds.reshape(-1), (c - h).reshape(-1), (c + h).reshape(-1)])


def check_float32(grid: OccupancyGrid, boxes: np.ndarray | None = None) -> None:
    """GridMapError unless float32 holds the grid's extent (finite, non-empty) and puts
    every box edge within :data:`MAX_EDGE_ERROR` cells of its exact position."""
    where = grid.source or "grid map"
    b = np.asarray(grid.bounds, np.float64)
    boxes = cover_boxes(grid) if boxes is None else boxes
    h, w = grid.occupied.shape
    with np.errstate(over="ignore", invalid="ignore"):
        b32, x32 = b.astype(np.float32), boxes.astype(np.float32)
    if not (np.all(np.isfinite(b)) and np.all(np.isfinite(b32)) and np.all(b32[:, 1] > b32[:, 0])):
        raise GridMapError(
            f"{where}: its extent ({w} x {h} cells of {grid.resolution:g} from "
            f"({grid.origin[0]:g}, {grid.origin[1]:g})) is {b.tolist()}, which "
            "float32 world coordinates cannot hold; use a resolution (or scale) "
            "giving a finite map of non-zero width"
        )
    exact = _edges(b, boxes)
    err = (
        float(
            np.max(
                np.abs(_edges(b32.astype(np.float64), x32.astype(np.float64)) - exact), initial=0.0
            )
        )
        / grid.resolution
    )
    if not err <= MAX_EDGE_ERROR:
        raise GridMapError(
            f"{where}: float32 world coordinates move its cell edges by up to "
            f"{err:.2g} cells (origin ({grid.origin[0]:g}, {grid.origin[1]:g}), "
            f"resolution {grid.resolution:g}); plan in the map's own frame: set "
            "its origin to [0, 0, 0] and add the origin to the planned paths"
        )


# ---------------------------------------------------------------------------
# MovingAI
# ---------------------------------------------------------------------------


def _read_text(path: Path) -> str:
    """The UTF-8 text of a map file; one :class:`GridMapError` line if unreadable."""
    try:
        return path.read_bytes().decode("utf-8").removeprefix("\ufeff")  # a BOM is no content
    except OSError as e:
        raise GridMapError(f"cannot read map file {str(path)!r}: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise GridMapError(f"{path}: not a text file ({e.reason} at byte {e.start})") from None


def _text_lines(path: Path) -> list[str]:
    text = _read_text(path)
    return text.replace("\r\n", "\n").replace("\r", "\n").split("\n")


def read_movingai(path, scale: float = 1.0) -> OccupancyGrid:
    """Reads a MovingAI benchmark ``.map`` (see the module docstring); one cell = ``scale`` units.

    Raises:
        GridMapError: naming the file and the offending line (1-based).
    """
    path = Path(path)
    try:
        scale = validation.number(scale, "scale", minimum=0, strict=True)
    except ValueError as e:
        raise GridMapError(f"{path}: {e}") from None
    lines = _text_lines(path)
    header: dict[str, str] = {}
    n = 0
    expected = ("type", "height", "width", "map")
    for key in expected:
        while n < len(lines) and not lines[n].strip():
            n += 1
        if n >= len(lines):
            raise GridMapError(
                f"{path}: ended before the {key!r} header line "
                "(expected 'type octile', 'height H', 'width W', 'map')"
            )
        parts = lines[n].split()
        if parts[0].lower() != key or (key == "map") != (len(parts) == 1) or len(parts) > 2:
            form = "map" if key == "map" else f"{key} <value>"
            raise GridMapError(
                f"{path}: line {n + 1} is {validation.short_repr(lines[n])}: expected {form!r}"
            )
        header[key] = parts[1] if len(parts) > 1 else ""
        n += 1
    if header["type"] != "octile":
        raise GridMapError(
            f"{path}: line 1: type {header['type']!r} is not supported (expected 'type octile')"
        )
    dims = {}
    for i, key in enumerate(("height", "width")):
        v = header[key]
        if not re.fullmatch(r"[0-9]+", v) or int(v) < 1:
            raise GridMapError(f"{path}: {key} {v!r} must be a positive integer")
        dims[key] = int(v)
    h, w = dims["height"], dims["width"]
    rows = []
    for i in range(h):
        k = n + i
        if k >= len(lines) or (not lines[k] and k == len(lines) - 1):
            raise GridMapError(
                f"{path}: has {i} map rows after the 'map' line, expected height {h}"
            )
        row = lines[k]
        if len(row) != w:
            raise GridMapError(
                f"{path}: line {k + 1} has {len(row)} characters, expected width {w}"
            )
        rows.append(row)
    extra = [k for k in range(n + h, len(lines)) if lines[k].strip()]
    if extra:
        raise GridMapError(
            f"{path}: line {extra[0] + 1}: unexpected content after the {h} map rows"
        )
    chars = np.frombuffer("".join(rows).encode("latin-1", "replace"), np.uint8).reshape(h, w)
    passable = np.isin(chars, np.frombuffer(MOVINGAI_PASSABLE.encode(), np.uint8))
    return OccupancyGrid(np.ascontiguousarray(~passable[::-1]), float(scale), (0.0, 0.0), str(path))


# ---------------------------------------------------------------------------
# ROS map_server
# ---------------------------------------------------------------------------


class _RosLoader(yaml.SafeLoader):
    """PyYAML's safe loader reading ``5e-2`` as a number, as map_server (yaml-cpp) does: YAML
    1.1, which PyYAML follows, needs a dot in a float (``5.0e-2``)."""


_RosLoader.yaml_implicit_resolvers = {
    k: list(v) for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_RosLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)

_ROS_KEYS = {"image", "resolution", "origin", "occupied_thresh", "free_thresh", "negate", "mode"}


def _read_pgm(path: Path) -> np.ndarray:
    """A PGM (P2 ASCII or P5 binary, maxval up to 65535) as ``(H, W)`` lightness in ``[0, 255]``."""
    data = path.read_bytes()
    magic = data[:2]
    if magic not in (b"P2", b"P5"):
        raise GridMapError(f"{path}: not a PGM image (magic {magic!r}, expected P2 or P5)")
    tokens: list[bytes] = []
    pos = 2
    while len(tokens) < 3:
        while pos < len(data) and data[pos : pos + 1].isspace():
            pos += 1
        if data[pos : pos + 1] == b"#":
            while pos < len(data) and data[pos : pos + 1] not in (b"\n", b"\r"):
                pos += 1
            continue
        start = pos
        while pos < len(data) and not data[pos : pos + 1].isspace() and data[pos : pos + 1] != b"#":
            pos += 1
        if start == pos:
            raise GridMapError(f"{path}: PGM header ends early (expected width, height, maxval)")
        tokens.append(data[start:pos])
    try:
        w, h, maxval = (int(t) for t in tokens)
    except ValueError:
        raise GridMapError(
            f"{path}: PGM header {b' '.join(tokens)!r} is not width height maxval"
        ) from None
    if w < 1 or h < 1 or not 0 < maxval < 65536:
        raise GridMapError(f"{path}: PGM header has width {w}, height {h}, maxval {maxval}")
    if magic == b"P5":
        pos += 1  # the single whitespace after maxval
        dtype = np.dtype(">u2") if maxval > 255 else np.dtype(np.uint8)
        need = w * h * dtype.itemsize
        if len(data) - pos < need:
            raise GridMapError(
                f"{path}: PGM pixel data is {len(data) - pos} bytes, expected {need}"
            )
        px = np.frombuffer(data, dtype, w * h, pos).reshape(h, w).astype(np.float64)
    else:
        body = re.sub(rb"#[^\n\r]*", b" ", data[pos:]).split()
        if len(body) != w * h:
            raise GridMapError(f"{path}: PGM has {len(body)} pixel values, expected {w} x {h}")
        try:
            px = np.asarray([int(t) for t in body], np.float64).reshape(h, w)
        except ValueError:
            raise GridMapError(f"{path}: PGM pixel values must be integers") from None
        if px.size and not (px.min() >= 0 and px.max() <= maxval):
            raise GridMapError(
                f"{path}: PGM pixel values must be in [0, {maxval}] (the header's "
                f"maxval), found {px.min():g}..{px.max():g}"
            )
    return px * (255.0 / maxval)


def _read_image(path: Path) -> np.ndarray:
    """The image's lightness ``(H, W)`` in ``[0, 255]`` (the mean of its colour channels)."""
    if not path.is_file():
        raise GridMapError(f"map image {str(path)!r} does not exist")
    with open(path, "rb") as f:
        head = f.read(2)
    if head in (b"P2", b"P5"):
        return _read_pgm(path)
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover - pillow is a dependency
        raise GridMapError(f"{path}: reading PNG maps needs pillow (pip install pillow)") from None
    try:
        with Image.open(path) as im:
            mode = im.mode
            if mode in ("1", "L", "I;16", "I;16B", "I"):
                px = np.asarray(im, np.float64)
                top = {"1": 1.0, "L": 255.0}.get(mode, 65535.0)
                return px * (255.0 / top)
            if mode in ("LA", "P", "PA", "RGBA", "RGB"):
                rgb = np.asarray(im.convert("RGB"), np.float64)
                return rgb.mean(axis=2)
            raise GridMapError(
                f"{path}: image mode {mode!r} is not supported (grayscale or RGB(A) PNG, or PGM)"
            )
    except GridMapError:
        raise
    except Exception as e:  # noqa: BLE001 - pillow raises many types for bad files
        raise GridMapError(f"{path}: not a readable PGM or PNG image ({e})") from None


def _ros_number(spec, key, path, *, lo=None, hi=None) -> float:
    if key not in spec:
        raise GridMapError(f"{path}: missing required field {key!r}")
    try:
        v = validation.number(spec[key], key)
    except ValueError as e:
        raise GridMapError(f"{path}: {e}") from None
    if (lo is not None and not v > lo) or (hi is not None and not v <= hi):
        raise GridMapError(
            f"{path}: {key} is {v:g}, expected a number in ({lo:g}, {hi:g}]"
            if hi is not None
            else f"{path}: {key} is {v:g}, expected a number > {lo:g}"
        )
    return v


def read_ros_map(path, unknown: str = "occupied") -> OccupancyGrid:
    """Reads a ROS ``map_server`` YAML and its image (see the module docstring).

    ``unknown``: ``"occupied"`` (default) or ``"free"``, what the unknown cells become.

    Raises:
        GridMapError: naming the file and the field (or the YAML line).
    """
    path = Path(path)
    if unknown not in UNKNOWN_POLICIES:
        raise GridMapError(f"unknown must be one of {UNKNOWN_POLICIES}, got {unknown!r}")
    text = _read_text(path)
    try:
        spec = yaml.load(text, Loader=_RosLoader)  # noqa: S506 (a SafeLoader)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else "YAML"
        raise GridMapError(
            f"{path}: {where}: not valid YAML ({getattr(e, 'problem', None) or e})"
        ) from None
    if not isinstance(spec, dict):
        raise GridMapError(
            f"{path}: expected a YAML mapping with image, resolution, origin, "
            f"occupied_thresh, free_thresh, negate"
        )
    extra = sorted(set(spec) - _ROS_KEYS, key=str)
    if extra:
        raise GridMapError(f"{path}: unknown field(s) {extra}; allowed: {sorted(_ROS_KEYS)}")
    image = spec.get("image")
    if not isinstance(image, str) or not image:
        raise GridMapError(
            f"{path}: field 'image' must be the image's file name, got "
            f"{validation.short_repr(image)}"
        )
    mode = spec.get("mode", "trinary")
    if mode != "trinary":
        raise GridMapError(f"{path}: mode {mode!r} is not supported (only 'trinary')")
    resolution = _ros_number(spec, "resolution", path, lo=0.0)
    occ_th = _ros_number(spec, "occupied_thresh", path, lo=0.0, hi=1.0)
    free_th = _ros_number(spec, "free_thresh", path, lo=-1e-300, hi=1.0)
    if not free_th < occ_th:
        raise GridMapError(f"{path}: free_thresh {free_th:g} must be < occupied_thresh {occ_th:g}")
    if "origin" not in spec:
        raise GridMapError(f"{path}: missing required field 'origin'")
    try:
        ox, oy, yaw = validation.number_list(spec["origin"], "origin", "[x, y, yaw]", length=3)
    except ValueError as e:
        raise GridMapError(f"{path}: {e}") from None
    if yaw != 0.0:
        raise GridMapError(
            f"{path}: origin yaw is {yaw:g}: only yaw 0 is supported (rotate the image instead)"
        )
    negate = spec.get("negate", 0)
    if negate not in (0, 1) or isinstance(negate, float):
        raise GridMapError(f"{path}: negate must be 0 or 1, got {validation.short_repr(negate)}")
    img = (path.parent / image) if not Path(image).is_absolute() else Path(image)
    v = _read_image(img)
    if negate:
        v = 255.0 - v
    p = (255.0 - v) / 255.0
    # map_server's trinary rule: occupied above occupied_thresh, free below free_thresh
    occupied = (p > occ_th) if unknown == "free" else ~((p < free_th) & ~(p > occ_th))
    return OccupancyGrid(np.ascontiguousarray(occupied[::-1]), resolution, (ox, oy), str(path))


def read_grid(path, *, unknown: str = "occupied", scale: float | None = None) -> OccupancyGrid:
    """A ROS map (``.yaml``/``.yml``) or a MovingAI map (``.map``), by the file's suffix.

    ``scale`` (MovingAI only): world units per cell (default 1).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".yaml", ".yml"):
        if scale is not None:
            raise GridMapError(
                f"{path}: 'scale' is for MovingAI maps; a ROS map's cell size is "
                "its YAML 'resolution'"
            )
        return read_ros_map(path, unknown)
    if suffix == ".map":
        return read_movingai(path, 1.0 if scale is None else scale)
    raise GridMapError(f"{path}: not a grid map (expected a ROS map .yaml or a MovingAI .map)")


# ---------------------------------------------------------------------------
# Writing, and a maze generator (tests, benchmarks, examples)
# ---------------------------------------------------------------------------


def write_movingai(path, occupied: np.ndarray) -> Path:
    """Writes ``occupied`` (``(H, W)`` bool, row 0 at the bottom as in :class:`OccupancyGrid`)
    as a MovingAI ``.map`` (``@`` blocked, ``.`` free; the file's first row is the top)."""
    occ = np.asarray(occupied, bool)
    h, w = occ.shape
    rows = ["".join("@" if v else "." for v in row) for row in occ[::-1]]
    return artifacts.write_text(
        path, f"type octile\nheight {h}\nwidth {w}\nmap\n" + "\n".join(rows) + "\n"
    )


def maze_grid(size: int = 256, corridor: int = 1, seed: int = 0) -> np.ndarray:
    """A perfect maze (depth-first backtracker) as ``(size, size)`` bool, True = wall.

    Rooms and passages are ``corridor`` cells wide, walls one cell (the layout of
    the MovingAI ``mazes`` set, e.g. ``maze512-8-0`` is 512 cells with corridors 8
    wide); cells past the last whole room are wall. Deterministic in ``seed``.
    """
    rng = np.random.default_rng(seed)
    step = corridor + 1
    m = (size - 1) // step
    if m < 1:
        raise ValueError(f"a {size}-cell maze has no room for corridors {corridor} wide")
    g = np.ones((size, size), bool)
    seen = np.zeros((m, m), bool)

    def room(r, c):
        g[r * step + 1 : r * step + 1 + corridor, c * step + 1 : c * step + 1 + corridor] = False

    stack = [(0, 0)]
    seen[0, 0] = True
    room(0, 0)
    while stack:
        r, c = stack[-1]
        nb = [
            (r + dr, c + dc)
            for dr, dc in ((0, 1), (1, 0), (0, -1), (-1, 0))
            if 0 <= r + dr < m and 0 <= c + dc < m and not seen[r + dr, c + dc]
        ]
        if not nb:
            stack.pop()
            continue
        r2, c2 = nb[rng.integers(len(nb))]
        seen[r2, c2] = True
        room(r2, c2)
        lo_r, lo_c = min(r, r2) * step + 1, min(c, c2) * step + 1
        g[
            lo_r : lo_r + corridor + (step if r != r2 else 0),
            lo_c : lo_c + corridor + (step if c != c2 else 0),
        ] = False
        stack.append((r2, c2))
    return g

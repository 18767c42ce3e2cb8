"""Users' grid maps (issue 18): the ROS map_server and MovingAI readers, the exact rectangle
cover, the wrapper JSON and scripts/import_map.py, and the scalable kernels (looped folds and
the broad-phase index) against the unrolled kernels and a per-cell shapely reference."""

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString, Point
from shapely.geometry import box as shapely_box
from shapely.ops import unary_union

import ntq_jax as nj
from ntq_jax import broadphase, grid_maps
from ntq_jax.envs import Env, EnvError
from ntq_jax.geometry import World
from ntq_jax.grid_maps import GridMapError, rectangle_cover
from ntq_jax.robots import batch as _batch
from ntq_jax.robots import robot_from_json

ROOT = Path(__file__).resolve().parents[1]

# ---------------------------------------------------------------------------
# MovingAI
# ---------------------------------------------------------------------------

MOVINGAI = "type octile\r\nheight 3\r\nwidth 5\r\nmap\r\n.@G.T\r\nS..WO\r\n@....\r\n"


def test_movingai_parses_crlf_and_terrain(tmp_path):
    p = tmp_path / "m.map"
    p.write_bytes(MOVINGAI.encode())
    g = grid_maps.read_movingai(p, scale=2.0)
    # row 0 is the bottom: the file's last line
    expected_top_down = np.array([[0, 1, 0, 0, 1], [0, 0, 0, 1, 1], [1, 0, 0, 0, 0]], bool)
    assert np.array_equal(g.occupied, expected_top_down[::-1])
    assert g.resolution == 2.0 and g.bounds == [[0.0, 10.0], [0.0, 6.0]]
    env = nj.make_env(p, scale=2.0)
    assert env.world.num_boxes == len(rectangle_cover(g.occupied)) and env.robot.kind == "point"


@pytest.mark.parametrize(
    "text, match",
    [
        (
            "type octile\nheight 2\nwidth 3\nmap\n...\n..\n",
            "line 6 has 2 characters, expected width 3",
        ),
        ("type octile\nheight 3\nwidth 3\nmap\n...\n...\n", "has 2 map rows .* expected height 3"),
        (
            "type octile\nwidth 3\nheight 2\nmap\n...\n...\n",
            "line 2 is 'width 3': expected 'height <value>'",
        ),
        ("type grid\nheight 1\nwidth 1\nmap\n.\n", "type 'grid' is not supported"),
        ("type octile\nheight x\nwidth 1\nmap\n.\n", "height 'x' must be a positive integer"),
        ("type octile\nheight 1\nwidth 1\nmap\n.\n.\n", "line 6: unexpected content"),
        ("", "ended before the 'type' header line"),
    ],
)
def test_movingai_errors_name_the_line(tmp_path, text, match):
    p = tmp_path / "bad.map"
    p.write_text(text)
    with pytest.raises(GridMapError, match=match):
        grid_maps.read_movingai(p)
    with pytest.raises(EnvError, match=match):  # through make_env: one EnvError line
        nj.make_env(p)


# ---------------------------------------------------------------------------
# ROS map_server
# ---------------------------------------------------------------------------

# lightness per pixel (top row first): 0 black = occupied, 254 white = free, 205 grey = unknown
PIXELS = np.array([[0, 254, 205, 254], [254, 254, 0, 100], [230, 205, 254, 0]], np.uint8)


def _yaml(path, image, negate=0, extra="", crlf=False):
    text = (
        f"# a map\nimage: {image}\nresolution: 0.5   # m/cell\norigin: [-1.0, 2.0, 0.0]\n"
        f"negate: {negate}\noccupied_thresh: 0.65\nfree_thresh: 0.196\n{extra}"
    )
    if crlf:
        text = text.replace("\n", "\r\n")
    path.write_bytes(text.encode())
    return path


def _pgm_p5(path, px, comment=True):
    h, w = px.shape
    head = (
        b"P5\n"
        + (b"# CREATOR: map_saver.cpp 0.050 m/pix\n" if comment else b"")
        + f"{w} {h}\n255\n".encode()
    )
    path.write_bytes(head + px.tobytes())


def _pgm_p2(path, px):
    h, w = px.shape
    body = "\n".join(" ".join(str(v) for v in row) for row in px)
    path.write_text(f"P2\n# ascii\n{w} {h}\n# max\n255\n{body}\n")


def _expected(px, negate=False, unknown="occupied"):
    v = 255.0 - px if negate else px.astype(float)
    p = (255.0 - v) / 255.0
    occ = p > 0.65
    free = p < 0.196
    out = occ if unknown == "free" else ~free
    return out[::-1]


@pytest.mark.parametrize("fmt", ["p5", "p2", "png_l", "png_rgb"])
def test_ros_map_trinary_formats(tmp_path, fmt):
    img = tmp_path / ("m.pgm" if fmt.startswith("p") else "m.png")
    if fmt == "p5":
        _pgm_p5(img, PIXELS)
    elif fmt == "p2":
        _pgm_p2(img, PIXELS)
    else:
        from PIL import Image

        im = Image.fromarray(PIXELS, "L")
        (im if fmt == "png_l" else im.convert("RGB")).save(img)
    y = _yaml(tmp_path / "m.yaml", img.name, crlf=(fmt == "p2"))
    g = grid_maps.read_ros_map(y)
    assert np.array_equal(g.occupied, _expected(PIXELS))
    assert g.resolution == 0.5 and g.origin == (-1.0, 2.0)
    assert g.bounds == [[-1.0, 1.0], [2.0, 3.5]]
    free = grid_maps.read_ros_map(y, unknown="free")
    assert np.array_equal(free.occupied, _expected(PIXELS, unknown="free"))


def test_ros_map_negate_and_world(tmp_path):
    _pgm_p5(tmp_path / "m.pgm", 255 - PIXELS)
    y = _yaml(tmp_path / "m.yaml", "m.pgm", negate=1)
    g = grid_maps.read_ros_map(y)
    assert np.array_equal(g.occupied, _expected(255 - PIXELS, negate=True))
    assert np.array_equal(g.occupied, _expected(PIXELS))
    env = nj.make_env(y, padding=0.05)
    # rasterising the imported world at the grid's own cells gives the grid back
    assert np.array_equal(env.rasterize(0.5, padding=0.0), g.occupied)
    assert env.padding == 0.05 and env.grid is not None


def _ros_yaml(path, image, resolution, origin):
    path.write_text(
        f"image: {image}\nresolution: {resolution}\norigin: {origin}\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    return path


@pytest.mark.parametrize(
    "resolution, origin, match",
    [
        ("1.0e+300", "[0.0, 0.0, 0.0]", r"float32 world coordinates cannot hold"),  # inf bounds
        ("1.0e-300", "[0.0, 0.0, 0.0]", r"float32 world coordinates cannot hold"),  # zero width
        ("1.0e+38", "[0.0, 0.0, 0.0]", r"float32 world coordinates cannot hold"),  # 4e38 > max
        (
            "0.05",
            "[500000.0, 4000000.0, 0.0]",
            r"move its cell edges by up to .* cells.*origin to "
            r"\[0, 0, 0\]",
        ),  # UTM: float32 spacing 3 cm > cells/100
    ],
)
def test_map_geometry_float32_cannot_hold_is_refused(tmp_path, resolution, origin, match, script):
    _pgm_p5(tmp_path / "m.pgm", PIXELS)
    y = _ros_yaml(tmp_path / "m.yaml", "m.pgm", resolution, origin)
    with pytest.raises(EnvError, match=match):
        nj.make_env(y)
    out = tmp_path / "env.json"
    proc = script("import_map", y, "--out", out)
    assert proc.returncode == 2 and proc.stderr.startswith("error: ") and not out.exists()
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize("origin", [(-51.2, -51.2), (0.0, 0.0), (1000.0, -2000.0)])
def test_map_geometry_float32_keeps_cell_edges_within_a_hundredth_of_a_cell(tmp_path, origin):
    """Accepted maps: every world box edge within MAX_EDGE_ERROR cells of the exact (float64)
    edge, and rasterising the world at the grid's cells gives the grid back."""
    _pgm_p5(tmp_path / "m.pgm", PIXELS)
    y = _ros_yaml(tmp_path / "m.yaml", "m.pgm", 0.05, f"[{origin[0]}, {origin[1]}, 0.0]")
    env = nj.make_env(y)
    g = grid_maps.read_ros_map(y)
    exact = grid_maps.cover_boxes(g)
    got = np.asarray(env.world.boxes, np.float64)[: len(exact)]
    edges = lambda b: np.concatenate([b[:, :2] - b[:, 2:], b[:, :2] + b[:, 2:]])  # noqa: E731
    assert np.max(np.abs(edges(got) - edges(exact))) <= grid_maps.MAX_EDGE_ERROR * 0.05
    assert np.array_equal(env.rasterize(0.05, padding=0.0), g.occupied)


@pytest.mark.parametrize(
    "extra, match",
    [
        ("resolution: 0\n", None),  # duplicate key: yaml keeps the last -> resolution 0
        ("mode: scale\n", "mode 'scale' is not supported"),
        ("foo: 1\n", r"unknown field\(s\) \['foo'\]"),
    ],
)
def test_ros_map_field_errors(tmp_path, extra, match):
    _pgm_p5(tmp_path / "m.pgm", PIXELS)
    y = _yaml(tmp_path / "m.yaml", "m.pgm", extra=extra)
    with pytest.raises(GridMapError, match=match or "resolution is 0, expected a number > 0"):
        grid_maps.read_ros_map(y)


@pytest.mark.parametrize(
    "text, match",
    [
        (
            "image: m.pgm\norigin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\nnegate: 0\n",
            "missing required field 'resolution'",
        ),
        (
            "image: m.pgm\nresolution: 0.1\norigin: [0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
            r"origin is \[0, 0\]: expected \[x, y, yaw\]",
        ),
        (
            "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0.5]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
            "origin yaw is 0.5: only yaw 0",
        ),
        (
            "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\noccupied_thresh: 0.1\nfree_thresh: 0.2\n",
            "free_thresh 0.2 must be < occupied_thresh 0.1",
        ),
        (
            "image: nothere.pgm\nresolution: 0.1\norigin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
            "map image .*nothere.pgm.* does not exist",
        ),
        (
            "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 2\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
            "negate must be 0 or 1",
        ),
        ("image: m.pgm\nresolution: 0.1: 2\norigin: [0, 0, 0]\n", "line 2: not valid YAML"),
    ],
)
def test_ros_yaml_errors(tmp_path, text, match):
    _pgm_p5(tmp_path / "m.pgm", PIXELS)
    y = tmp_path / "m.yaml"
    y.write_text(text)
    with pytest.raises(GridMapError, match=match):
        grid_maps.read_ros_map(y)


def test_pgm_errors(tmp_path):
    y = _yaml(tmp_path / "m.yaml", "m.pgm")
    (tmp_path / "m.pgm").write_bytes(b"P5\n4 3\n255\n" + b"\0" * 5)
    with pytest.raises(GridMapError, match="PGM pixel data is 5 bytes, expected 12"):
        grid_maps.read_ros_map(y)
    (tmp_path / "m.pgm").write_bytes(b"P5\n4 x\n255\n")
    with pytest.raises(GridMapError, match="is not width height maxval"):
        grid_maps.read_ros_map(y)
    (tmp_path / "m.pgm").write_bytes(b"GIF89a")
    with pytest.raises(GridMapError, match="not a readable PGM or PNG image"):
        grid_maps.read_ros_map(y)


# ---------------------------------------------------------------------------
# Rectangle cover
# ---------------------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 24), st.integers(1, 24), st.floats(0.0, 1.0), st.integers(0, 2**31))
def test_rectangle_cover_is_exact(h, w, density, seed):
    occ = np.random.default_rng(seed).random((h, w)) < density
    rects = rectangle_cover(occ)
    count = np.zeros((h, w), np.int32)
    for r0, c0, r1, c1 in rects:
        assert 0 <= r0 < r1 <= h and 0 <= c0 < c1 <= w
        count[r0:r1, c0:c1] += 1
    assert np.array_equal(count, occ.astype(np.int32))  # every occupied cell once, no free cell
    assert np.array_equal(rectangle_cover(occ), rects)  # deterministic


def test_rectangle_cover_merges():
    occ = np.zeros((10, 12), bool)
    occ[2:8, 3:9] = True  # one block
    occ[0, :] = True  # one wall
    assert len(rectangle_cover(occ)) == 2
    maze = grid_maps.maze_grid(64, corridor=1)
    assert len(rectangle_cover(maze)) < maze.sum() / 2


# ---------------------------------------------------------------------------
# Wrapper JSON, import_map.py, make_env arguments
# ---------------------------------------------------------------------------


def test_wrapper_json_and_import_script(tmp_path, script):
    (tmp_path / "maps").mkdir()
    grid_maps.write_movingai(tmp_path / "maps" / "maze.map", grid_maps.maze_grid(32, 2, seed=3))
    robot = {"kind": "rigid_body", "length": 0.6, "width": 0.2}
    spec = {"name": "maze", "grid": "maps/maze.map", "robot": robot, "padding": 0.1, "scale": 0.5}
    (tmp_path / "maze.json").write_text(json.dumps(spec))
    env = nj.make_env(tmp_path / "maze.json")  # grid path relative to the JSON
    assert env.name == "maze" and env.grid.resolution == 0.5 and env.robot.kind == "rigid_body"
    direct = nj.make_env(tmp_path / "maps" / "maze.map", robot=robot, padding=0.1, scale=0.5)
    assert direct.content_hash() == env.content_hash()
    out = tmp_path / "converted.json"
    r = subprocess.run(
        [
            sys.executable,
            str(ROOT / "scripts" / "import_map.py"),
            str(tmp_path / "maps" / "maze.map"),
            "--robot",
            json.dumps(robot),
            "--padding",
            "0.1",
            "--scale",
            "0.5",
            "--name",
            "maze",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert "boxes" in r.stdout
    assert nj.make_env(out).content_hash() == env.content_hash()
    r = script("import_map", tmp_path / "maps" / "maze.map", "--robot", "{bad")
    assert (
        r.returncode == 2 and r.stderr.count("\n") == 1 and "--robot is not valid JSON" in r.stderr
    )
    r = script("import_map", tmp_path / "maps" / "maze.map", "--out", tmp_path)
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert f"--out {tmp_path} is a folder; give a file name" in r.stderr


@pytest.mark.parametrize(
    "spec, match",
    [
        (
            {"grid": "m.map", "robot": {"kind": "point"}, "boxes": []},
            r"unknown key\(s\) \['boxes'\]",
        ),
        ({"grid": "m.map"}, "missing required key 'robot'"),
        (
            {"grid": "m.map", "robot": {"kind": "point"}, "unknown": "free"},
            "'unknown' is for ROS maps",
        ),
        (
            {"grid": "m.map", "robot": {"kind": "point"}, "scale": -1},
            "scale must be a finite number > 0",
        ),
        ({"grid": "nothere.map", "robot": {"kind": "point"}}, "cannot read map file"),
        ({"grid": 3, "robot": {"kind": "point"}}, "grid must be the path"),
    ],
)
def test_wrapper_json_errors(tmp_path, spec, match):
    (tmp_path / "m.map").write_text("type octile\nheight 1\nwidth 2\nmap\n.@\n")
    (tmp_path / "w.json").write_text(json.dumps(spec))
    with pytest.raises(EnvError, match=match):
        nj.make_env(tmp_path / "w.json")


def test_make_env_grid_arguments_only_for_grids():
    with pytest.raises(EnvError, match="are for grid map files"):
        nj.make_env("point/0", padding=0.3)


# ---------------------------------------------------------------------------
# Kernels: looped and indexed against unrolled, and against a per-cell reference
# ---------------------------------------------------------------------------

ROBOTS = [
    ({"kind": "point"}, 0.3),
    ({"kind": "rigid_body", "length": 1.0, "width": 0.4}, 0.2),
    ({"kind": "nlink", "link_lengths": [5.0, 5.0], "base": [25.0, 25.0]}, 0.2),
]


def _random_world(n, seed=1):
    rng = np.random.default_rng(seed)
    return World.create(
        [[0, 50], [0, 50]], np.c_[rng.uniform(0, 50, (n, 2)), rng.uniform(0.1, 0.8, (n, 2))]
    )


def _shared_world():
    """The map of test_looped_and_indexed_equal_unrolled (and test_gamma_chunk_...): the point
    and rigid cases of test_indexed_equals_looped use it too, so their indexed and looped
    programs at the robot's padding (valid_states' and steer_to_pairs' chunk shapes, the
    world traced) are compiled once for both tests. It is equivalent to the 150-box map for
    what that test proves: above UNROLL_MAX (so an index and the looped fold), the same
    index code paths (no blocked-cell bitmap, candidate lists within INDEX_UNROLL_MAX; the
    rigid body's lists are 8 long on both maps), and over a hundred of the test's 3000
    states invalid and hundreds of its motions blocked. The arm keeps the 150-box map: there
    its lists are 8 long (two blocks of the clearances' looped candidate fold), here 4."""
    return _random_world(broadphase.UNROLL_MAX + 7, seed=5)


def _pairs(env, rng, n, spread):
    lo, hi = (np.asarray(v) for v in env.robot.config_bounds(env.world))
    a = rng.uniform(lo, hi, (n, env.dim)).astype(np.float32)
    return a, (a + rng.normal(0, spread, a.shape)).astype(np.float32)


@pytest.mark.parametrize("robot, pad", ROBOTS, ids=["point", "rigid", "nlink"])
def test_indexed_equals_looped(robot, pad):
    """The broad phase against the looped fold over every box (same per-box formulas)."""
    rng = np.random.default_rng(0)
    world = _random_world(150) if robot["kind"] == "nlink" else _shared_world()
    env = Env("x", robot_from_json(robot), world, pad)
    assert env.world.index is not None
    plain = Env("x", env.robot, world, pad)
    object.__setattr__(plain, "world", dataclasses.replace(env.world, index=None))
    a, b = _pairs(env, rng, 3000, 0.5 if robot["kind"] == "nlink" else 3.0)
    # is_valid through valid_states' chunk program (what Env.is_valid runs for up to
    # CHECK_CHUNK states; 3000 would be padded to a size of its own): the programs
    # test_looped_and_indexed_equal_unrolled's 2000 states run
    valid = lambda e, p: _batch.valid_states(e.robot, e.world, a, p)  # noqa: E731
    for p in (pad, pad + 5.0):  # pad + 5 is beyond the index's reach: the looped path
        np.testing.assert_array_equal(valid(env, p), valid(plain, p))
    # the rigid body's and the arm's discretised steer_to is is_valid along the motion (the
    # same work queue either way); the point robot's has its own broad-phase queue
    if robot["kind"] != "nlink":
        np.testing.assert_array_equal(env.steer_to(a, b, pad), plain.steer_to(a, b, pad))
    if robot["kind"] == "point":
        return
    # the certified check's clearances: exact below the index's cap, at least the cap above it,
    # and positive exactly for the valid states
    clear = jax.jit(jax.vmap(env.robot.part_clearances, in_axes=(0, None, None)), static_argnums=2)
    got, ref = np.asarray(clear(a, env.world, pad)), np.asarray(clear(a, plain.world, pad))
    rho = getattr(env.robot, "half_diagonal", 0.0)
    reach = env.world.index.reach
    cap = reach - rho - pad if rho else 0.5 * (reach + pad) - pad
    exact = ref < cap - 1e-4
    np.testing.assert_allclose(got[exact], ref[exact], rtol=0, atol=1e-5)
    assert np.all(got[~exact] >= cap - 1e-4) and np.all(ref[~exact] >= got[~exact] - 1e-5)
    np.testing.assert_array_equal(np.all(got > 0, axis=1), valid(env, pad))


@pytest.mark.parametrize("robot, pad", ROBOTS[:2], ids=["point", "rigid"])
def test_looped_and_indexed_equal_unrolled(robot, pad, monkeypatch):
    """Just above UNROLL_MAX boxes: the unrolled kernels (UNROLL_MAX raised) are the reference."""
    rng = np.random.default_rng(2)
    world = _shared_world()
    env = Env("x", robot_from_json(robot), world, pad)
    a, b = _pairs(env, rng, 2000, 3.0)
    point = robot["kind"] == "point"

    def answers(e):
        return [np.asarray(e.is_valid(a, pad))] + (
            [np.asarray(e.steer_to(a, b, pad))] if point else []
        )

    def kernels():  # new functions: traced afresh, with the UNROLL_MAX of the moment
        r = env.robot
        return [lambda w, x, y: jax.vmap(r.is_valid, in_axes=(1, None, None))(x.T, w, pad)] + (
            [lambda w, x, y: r.steer_to_batch(x.T, y.T, w, pad)] if point else []
        )

    got = answers(env)
    looped = Env("x", env.robot, world, pad)
    object.__setattr__(looped, "world", world)
    got_looped = answers(looped)
    monkeypatch.setattr(broadphase, "UNROLL_MAX", 10**6)
    unrolled = Env("x", env.robot, world, pad)
    assert unrolled.world.index is None
    # the reference: its own programs, traced while every box unrolls; the compiled
    # programs of the library's entry points are left as they are (traced at UNROLL_MAX)
    traced = [jax.jit(f).trace(world, a, b) for f in kernels()]
    monkeypatch.undo()
    # no loop over the boxes (lax.scan, which the kernels at UNROLL_MAX have) is left in them
    assert all(" scan[" not in str(t.jaxpr) for t in traced)
    ref = [np.asarray(t.lower().compile()(world, a, b)) for t in traced]
    for g, gl, r in zip(got, got_looped, ref):
        np.testing.assert_array_equal(g, r)
        np.testing.assert_array_equal(gl, r)


@pytest.mark.parametrize("pad", [0.0, 0.15])
def test_imported_grid_agrees_with_cells(tmp_path, pad):
    """is_valid and steer_to on an imported ROS map against shapely on the occupied cells."""
    rng = np.random.default_rng(7)
    occ = rng.random((30, 40)) < 0.12
    occ[10:20, 5] = True
    px = np.where(occ[::-1], 0, 254).astype(np.uint8)
    _pgm_p5(tmp_path / "r.pgm", px)
    y = _yaml(tmp_path / "r.yaml", "r.pgm")
    env = nj.make_env(y, padding=pad)
    assert env.world.num_boxes > broadphase.UNROLL_MAX and env.world.index is not None
    g = env.grid
    assert np.array_equal(g.occupied, occ)
    cells = unary_union(
        [
            shapely_box(-1 + c * 0.5, 2 + r * 0.5, -1 + (c + 1) * 0.5, 2 + (r + 1) * 0.5)
            for r, c in zip(*np.nonzero(occ))
        ]
    )
    (x0, x1), (y0, y1) = g.bounds
    pts = np.c_[rng.uniform(x0, x1, 600), rng.uniform(y0, y1, 600)].astype(np.float32)
    valid = np.asarray(env.is_valid(pts))
    ref = np.array([cells.distance(Point(p)) > pad for p in pts.astype(np.float64)])
    np.testing.assert_array_equal(valid, ref)
    a = pts[:300]
    b = (a + rng.normal(0, 2.0, a.shape)).astype(np.float32)
    free = np.asarray(env.steer_to(a, b))
    inside = lambda p: x0 <= p[0] <= x1 and y0 <= p[1] <= y1  # noqa: E731
    ref = np.array(
        [
            inside(p) and inside(q) and cells.distance(LineString([p, q])) > pad
            for p, q in zip(a.astype(np.float64), b.astype(np.float64))
        ]
    )
    np.testing.assert_array_equal(free, ref)
    assert 0 < free.sum() < len(free)


def test_astar_plans_on_the_maps_own_grid(tmp_path):
    p = grid_maps.write_movingai(tmp_path / "m.map", grid_maps.maze_grid(33, 3, seed=1))
    env = nj.make_env(p)
    from ntq_jax.planners.astar_planner import config_grid

    assert np.array_equal(config_grid(env, 1.0, 0.0).occ, env.grid.occupied)
    s = env.sample_states(jax.random.key(0), 8)
    res = nj.plan(env, np.stack([s[:4], s[4:]], 1), "astar", padding=0.0, resolution=0.1)
    assert res.info["map_grid"] and res.info["resolution"] == 1.0
    assert (res.status == 0).all()
    with pytest.raises(ValueError, match="limited to 500 obstacles"):
        nj.plan(nj.make_env(_big_map(tmp_path)), s[None, :2], "visgraph")


def _big_map(tmp_path):
    return grid_maps.write_movingai(tmp_path / "big.map", grid_maps.maze_grid(128, 1, seed=2))


def test_make_env_takes_a_robot_kind_and_refuses_what_it_cannot_use(tmp_path):
    from ntq_jax import make_env
    from ntq_jax.envs import EnvError

    p = tmp_path / "m.map"
    p.write_bytes(MOVINGAI.encode())
    assert make_env(str(p), robot="point").robot.kind == "point"  # the CLI's kind strings
    assert make_env(str(p), robot={"kind": "point"}).robot.kind == "point"
    with pytest.raises(EnvError, match="robot must be a kind"):
        make_env(str(p), robot=3)
    with pytest.raises(EnvError, match="unknown='free' is for ROS maps"):
        make_env(str(p), unknown="free")


def test_ros_exponents_bom_and_p2_pixel_range(tmp_path):
    """map_server reads ``resolution: 5e-2`` as a number (PyYAML alone: a string); a BOM is
    no content; P2 pixels outside [0, maxval] are refused."""
    _pgm_p5(tmp_path / "m.pgm", PIXELS)
    y = tmp_path / "m.yaml"
    y.write_bytes(
        (
            "\ufeffimage: m.pgm\nresolution: 5e-2\n"
            "origin: [-1e0, 2.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\n"
            "free_thresh: 0.196\n"
        ).encode()
    )
    g = grid_maps.read_ros_map(y)
    assert g.resolution == 0.05 and g.origin == (-1.0, 2.0)
    np.testing.assert_array_equal(g.occupied, _expected(PIXELS))
    m = tmp_path / "bom.map"
    m.write_bytes(("\ufeff" + MOVINGAI).encode())
    np.testing.assert_array_equal(
        grid_maps.read_movingai(m).occupied, grid_maps.read_movingai(_plain(tmp_path)).occupied
    )
    for bad in ("256", "-1"):
        img = tmp_path / f"bad{bad}.pgm"
        img.write_text(f"P2\n2 1\n255\n0 {bad}\n")
        with pytest.raises(grid_maps.GridMapError, match=r"pixel values must be in \[0, 255\]"):
            grid_maps.read_ros_map(_yaml(tmp_path / f"bad{bad}.yaml", img.name))


def _plain(tmp_path):
    p = tmp_path / "plain.map"
    p.write_bytes(MOVINGAI.encode())
    return p


def test_large_maps_are_drawn_as_one_image_matching_the_boxes(monkeypatch):
    """Above IMAGE_MAP_BOXES boxes draw_map draws one image (no patch per box): every pixel
    whose square lies inside a box is dark, every pixel farther than the padding light."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ntq_jax import plotting

    occ = grid_maps.maze_grid(40, 1, 0)
    g = grid_maps.OccupancyGrid(occ, 1.0)
    boxes = grid_maps.cover_boxes(g)
    spec = {"robot": {"kind": "point"}, "bounds": g.bounds, "boxes": boxes.tolist(), "padding": 0.1}
    monkeypatch.setattr(plotting, "IMAGE_MAP_BOXES", len(boxes) - 1)
    monkeypatch.setattr(plotting, "IMAGE_PIXELS", 400)
    fig, ax = plt.subplots()
    plotting.draw_map(ax, spec, padded=True)
    assert len(ax.images) == 1 and len(ax.patches) == 0
    img = ax.images[0].get_array()
    n = img.shape[0]
    px = (np.arange(n) + 0.5) * (40 / n)  # pixel centres (square map, one scale)
    cy, cx = np.meshgrid(px, px, indexing="ij")
    inside = occ[np.floor(cy).astype(int), np.floor(cx).astype(int)]
    # Chebyshev distance from each pixel centre to the nearest occupied cell (the padding is
    # drawn with square corners)
    far = np.ones_like(inside)
    for r, c in zip(*np.nonzero(occ)):
        dx = np.maximum(np.abs(cx - (c + 0.5)) - 0.5, 0)
        dy = np.maximum(np.abs(cy - (r + 0.5)) - 0.5, 0)
        far &= np.maximum(dx, dy) > 0.1 + 2 * 40 / n
    assert np.all(img[inside] == np.float32(0.35))
    assert np.all(img[far] == 1.0) and far.any()
    plt.close(fig)


def test_gamma_chunk_of_a_large_map_keeps_memory_small():
    """gamma_nt's default chunk on an indexed map is INDEXED_POINT_CHUNK (its work queue
    keeps ~0.5 kB per pair: 2**22 pairs took 2.7 GB on a 73k-box map); presets keep 2**22."""
    from ntq_jax import gamma as G

    env = nj.make_env("point/0")
    assert env.world.index is None and G.default_chunk(env.robot, env.world) == 1 << 22
    assert G.default_chunk(nj.make_env("rigid/0").robot) == 1 << 15
    world = _shared_world()
    big = Env("many", env.robot, world, 0.0)
    assert big.world.index is not None
    assert G.default_chunk(big.robot, big.world) == G.INDEXED_POINT_CHUNK == 1 << 18

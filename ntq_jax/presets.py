"""The preset environments, as JSON-ready dicts (the format of :mod:`ntq_jax.envs`).

Layouts are designed so that gamma_nt on the evaluation geometry (padding 0),
measured over >= 1e6 uniform queries, is within +-0.03 of the paper's value
(see the table below and BENCHMARKS.md). Paddings are the paper's: 0.8 point,
0.4 rigid body, 0.8 arm. Every layout was tuned by bisecting one scale
parameter (a wall length, a door width, a block size or the arm's link
length) against the paper's gamma_nt; every narrow passage stays passable at
the data-generation padding (the free space at the environment's padding is
one connected component, checked on a fine grid / roadmap).

==========  =========  ===================================================================
preset      paper      layout
==========  =========  ===================================================================
point/0     0.311      five scattered blocks (1.2-1.8 wide)
point/1     0.402      a long wall from the left edge (10.3 long) and two 2.5 x 2.5 blocks
point/2     0.414      two staggered walls (9.7 long) from opposite edges: an S-shaped passage
point/3     0.628      four rooms (cross of walls with 3.0-wide doors) and two blocks
rigid/0     0.503      three scattered blocks
rigid/1     0.659      two full-height walls, each with a 1.8-wide door, doors staggered
rigid/2     0.556      a wall from the left edge (6.0 long) and two blocks
rigid/3     0.690      four rooms (2.6-wide doors) with a block in each room
nlink/2     0.225      4 blocks at radius 5-7 around the base; 2 links of 2.61 (reach 5.22)
nlink/4     0.366      the same 4 blocks; 4 links of 1.73 (reach 6.92)
nlink/6     0.608      the same 4 blocks; 6 links of 1.67 (reach 10.02)
==========  =========  ===================================================================

Robots. Point: a point in [0, 20]^2. Rigid body: a 1.2 x 0.4 rectangle in
[0, 10]^2 (unchanged); every door (1.8 / 2.6 wide) is wider than the
rectangle's width plus twice the padding (0.4 + 2 * 0.4 = 1.2). Arms: base at
the centre of the [-10, 10]^2 workspace, equal links; the three arms share one
obstacle layout and the arm grows with the number of links (longer arms reach
more of the blocks, hence the paper's rising gamma_nt; with a fixed arm
length, more links fold the arm and lower gamma_nt instead). The nearest
block is 4.9 from the base, farther than the first link plus the padding for
every arm, so no obstacle can stop the first joint (with joints in [-pi, pi]
and no wrap-around, such an obstacle would cut the configuration space in
two). The 6-link arm (reach 10.02) leaves the workspace only in nearly fully
stretched, axis-aligned poses.
"""

from __future__ import annotations

PAPER_GAMMA = {
    "point/0": 0.311,
    "point/1": 0.402,
    "point/2": 0.414,
    "point/3": 0.628,
    "rigid/0": 0.503,
    "rigid/1": 0.659,
    "rigid/2": 0.556,
    "rigid/3": 0.690,
    "nlink/2": 0.225,
    "nlink/4": 0.366,
    "nlink/6": 0.608,
}

_POINT = {"kind": "point"}
_RIGID = {
    "kind": "rigid_body",
    "length": 1.2,
    "width": 0.4,
    "angle_weight": 0.5,
    "resolution": 0.05,
}

# Boxes are [cx, cy, half_w, half_h].
_ARM_BLOCKS = [
    [6.108, 2.223, 1.0, 1.0],
    [-2.052, 5.638, 1.2, 0.8],
    [-6.39, -2.326, 0.8, 1.2],
    [2.121, -5.826, 1.0, 1.0],
]
_ARM_LINK = {2: 2.61, 4: 1.73, 6: 1.67}


def _arm(n: int) -> dict:
    return {
        "kind": "nlink",
        "link_lengths": [_ARM_LINK[n]] * n,
        "base": [0.0, 0.0],
        "resolution": 0.02,
    }


def _point(name: str, boxes: list) -> dict:
    return {
        "name": name,
        "robot": _POINT,
        "bounds": [[0, 20], [0, 20]],
        "padding": 0.8,
        "boxes": boxes,
        "discs": [],
    }


def _rigid(name: str, boxes: list) -> dict:
    return {
        "name": name,
        "robot": _RIGID,
        "bounds": [[0, 10], [0, 10]],
        "padding": 0.4,
        "boxes": boxes,
        "discs": [],
    }


def _nlink(n: int) -> dict:
    return {
        "name": f"nlink/{n}",
        "robot": _arm(n),
        "bounds": [[-10, 10], [-10, 10]],
        "padding": 0.8,
        "boxes": [list(b) for b in _ARM_BLOCKS],
        "discs": [],
    }


PRESETS: dict[str, dict] = {
    "point/0": _point(
        "point/0",
        [
            [5.0, 5.5, 0.8, 0.6],
            [14.0, 4.5, 0.6, 0.9],
            [10.0, 11.0, 0.8, 0.8],
            [4.5, 15.0, 0.6, 0.9],
            [15.0, 15.0, 0.9, 0.6],
        ],
    ),
    "point/1": _point(
        "point/1", [[5.15, 10.0, 5.15, 0.4], [14.25, 4.75, 1.25, 1.25], [5.25, 15.25, 1.25, 1.25]]
    ),
    "point/2": _point("point/2", [[7.0, 4.85, 0.4, 4.85], [13.0, 15.15, 0.4, 4.85]]),
    "point/3": _point(
        "point/3",
        [
            # walls x = 10 and y = 10, each half with a 3.0-wide door
            [10.0, 1.75, 0.4, 1.75],
            [10.0, 10.0, 0.4, 3.5],
            [10.0, 18.25, 0.4, 1.75],
            [1.75, 10.0, 1.75, 0.4],
            [8.05, 10.0, 1.55, 0.4],
            [11.95, 10.0, 1.55, 0.4],
            [18.25, 10.0, 1.75, 0.4],
            # furniture
            [5.0, 5.0, 1.4, 1.4],
            [15.0, 15.0, 1.4, 0.9],
        ],
    ),
    "rigid/0": _rigid(
        "rigid/0", [[2.8, 2.6, 0.675, 0.525], [7.2, 3.6, 0.525, 0.75], [4.2, 7.2, 0.75, 0.525]]
    ),
    "rigid/1": _rigid(
        "rigid/1",
        [
            [3.3, 3.05, 0.2, 3.05],
            [3.3, 8.95, 0.2, 1.05],
            [6.7, 1.05, 0.2, 1.05],
            [6.7, 6.95, 0.2, 3.05],
        ],
    ),
    "rigid/2": _rigid(
        "rigid/2", [[3.0, 5.0, 3.0, 0.2], [7.5, 2.5, 0.7, 0.7], [2.6, 7.8, 0.6, 0.6]]
    ),
    "rigid/3": _rigid(
        "rigid/3",
        [
            # walls x = 5 and y = 5, each half with a 2.6-wide door
            [5.0, 0.6, 0.2, 0.6],
            [5.0, 5.0, 0.2, 1.2],
            [5.0, 9.4, 0.2, 0.6],
            [0.6, 5.0, 0.6, 0.2],
            [4.3, 5.0, 0.5, 0.2],
            [5.7, 5.0, 0.5, 0.2],
            [9.4, 5.0, 0.6, 0.2],
            # a block in each room
            [1.5, 2.0, 0.5, 0.5],
            [7.8, 7.9, 0.5, 0.5],
            [7.6, 2.0, 0.5, 0.5],
            [2.2, 7.6, 0.5, 0.5],
        ],
    ),
    "nlink/2": _nlink(2),
    "nlink/4": _nlink(4),
    "nlink/6": _nlink(6),
}

"""The preset environments, as JSON-ready dicts (the format of :mod:`ntq_jax.envs`).

Layouts are designed so that gamma_nt on the evaluation geometry (padding 0),
measured over >= 1e6 uniform queries, is within +-0.03 of the paper's value
(see the table below and BENCHMARKS.md). Paddings are the paper's: 0.8 point,
0.4 rigid body, 0.8 arm.

==========  =========  =========================================
preset      paper      layout
==========  =========  =========================================
point/0     0.311      a few scattered blocks
point/1     0.402      blocks and a long wall
point/2     0.414      two walls with gaps
point/3     0.628      rooms and corridors with narrow doors
rigid/0     0.503      scattered blocks
rigid/1     0.659      walls with doors
rigid/2     0.556      blocks and a wall
rigid/3     0.690      cluttered rooms
nlink/2     0.225      arm amid blocks
nlink/4     0.366      arm amid blocks
nlink/6     0.608      arm amid blocks
==========  =========  =========================================
"""

from __future__ import annotations

PAPER_GAMMA = {
    "point/0": 0.311, "point/1": 0.402, "point/2": 0.414, "point/3": 0.628,
    "rigid/0": 0.503, "rigid/1": 0.659, "rigid/2": 0.556, "rigid/3": 0.690,
    "nlink/2": 0.225, "nlink/4": 0.366, "nlink/6": 0.608,
}

_POINT = {"kind": "point"}
_RIGID = {"kind": "rigid_body", "length": 1.2, "width": 0.4, "angle_weight": 0.5,
          "resolution": 0.05}


def _arm(n: int) -> dict:
    return {"kind": "nlink", "link_lengths": [7.0 / n] * n, "base": [0.0, 0.0],
            "resolution": 0.02}


PRESETS: dict[str, dict] = {
    "point/0": {"name": "point/0", "robot": _POINT, "bounds": [[0, 20], [0, 20]], "padding": 0.8,
                "boxes": [[5, 5, 1.5, 1.5], [14, 6, 2, 1], [9, 13, 1.5, 2.5], [16, 15, 1, 1.5],
                          [4, 16, 1, 1]],
                "discs": []},
    "point/1": {"name": "point/1", "robot": _POINT, "bounds": [[0, 20], [0, 20]], "padding": 0.8,
                "boxes": [[10, 10, 6, 0.6], [4, 4, 1.5, 1.5], [15, 4, 1.5, 1.5], [5, 16, 1.5, 1],
                          [15, 16, 1, 1.5]],
                "discs": []},
    "point/2": {"name": "point/2", "robot": _POINT, "bounds": [[0, 20], [0, 20]], "padding": 0.8,
                "boxes": [[7, 4, 0.5, 4], [7, 15, 0.5, 5], [13, 5, 0.5, 5], [13, 16, 0.5, 4]],
                "discs": []},
    "point/3": {"name": "point/3", "robot": _POINT, "bounds": [[0, 20], [0, 20]], "padding": 0.8,
                "boxes": [[6.5, 4, 0.5, 4], [6.5, 15, 0.5, 5], [13.5, 5, 0.5, 5],
                          [13.5, 16, 0.5, 4], [3, 10, 3, 0.5], [17, 10.5, 3, 0.5],
                          [10, 8, 1.5, 1.5]],
                "discs": []},
    "rigid/0": {"name": "rigid/0", "robot": _RIGID, "bounds": [[0, 10], [0, 10]], "padding": 0.4,
                "boxes": [[2.5, 2.5, 0.8, 0.8], [7, 3, 1, 0.6], [4.5, 7, 0.8, 1.2], [8, 8, 0.6, 0.6]],
                "discs": []},
    "rigid/1": {"name": "rigid/1", "robot": _RIGID, "bounds": [[0, 10], [0, 10]], "padding": 0.4,
                "boxes": [[3.3, 2.5, 0.3, 2.5], [3.3, 8.5, 0.3, 1.5], [6.7, 1.5, 0.3, 1.5],
                          [6.7, 7.5, 0.3, 2.5]],
                "discs": []},
    "rigid/2": {"name": "rigid/2", "robot": _RIGID, "bounds": [[0, 10], [0, 10]], "padding": 0.4,
                "boxes": [[5, 5, 3, 0.3], [2, 2, 0.8, 0.8], [8, 8, 0.8, 0.8]],
                "discs": []},
    "rigid/3": {"name": "rigid/3", "robot": _RIGID, "bounds": [[0, 10], [0, 10]], "padding": 0.4,
                "boxes": [[3.3, 2.5, 0.3, 2.5], [3.3, 8.5, 0.3, 1.5], [6.7, 1.5, 0.3, 1.5],
                          [6.7, 7.5, 0.3, 2.5], [5, 5, 0.7, 0.7]],
                "discs": []},
    "nlink/2": {"name": "nlink/2", "robot": _arm(2), "bounds": [[-10, 10], [-10, 10]],
                "padding": 0.8, "boxes": [[5, 4, 1, 1], [-4, 5, 1, 1]], "discs": []},
    "nlink/4": {"name": "nlink/4", "robot": _arm(4), "bounds": [[-10, 10], [-10, 10]],
                "padding": 0.8, "boxes": [[5, 4, 1, 1], [-4, 5, 1, 1], [0, -5, 1.5, 0.8]],
                "discs": []},
    "nlink/6": {"name": "nlink/6", "robot": _arm(6), "bounds": [[-10, 10], [-10, 10]],
                "padding": 0.8, "boxes": [[5, 4, 1, 1], [-4, 5, 1, 1], [0, -5, 1.5, 0.8],
                                          [-5, -3, 0.8, 0.8]],
                "discs": []},
}

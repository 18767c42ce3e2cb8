"""Drawing a large map: one patch per box against one image (``plotting.draw_map``).

    python benchmarks/bench_draw.py [--size 300]

Draws the same maze (``grid_maps.maze_grid(size, 1, 0)``, padding drawn) both
ways in one process, saves each figure at 100 dpi and prints the seconds and
their ratio.
"""

from __future__ import annotations

import argparse
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from ntq_jax import grid_maps, plotting  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=300, help="maze side in cells (default 300)")
    args = ap.parse_args()
    g = grid_maps.OccupancyGrid(grid_maps.maze_grid(args.size, 1, 0), 1.0)
    boxes = grid_maps.cover_boxes(g)
    spec = {"robot": {"kind": "point"}, "bounds": g.bounds, "boxes": boxes.tolist(), "padding": 0.3}
    seconds = {}
    for label, threshold in (("patches", 10**12), ("image", plotting.IMAGE_MAP_BOXES)):
        plotting.IMAGE_MAP_BOXES = threshold
        t0 = time.perf_counter()
        fig, ax = plt.subplots()
        plotting.draw_map(ax, spec, padded=True)
        fig.savefig(f"/tmp/bench_draw_{label}.png", dpi=100)
        plt.close(fig)
        seconds[label] = time.perf_counter() - t0
    print(
        f"{len(boxes)} boxes: patches {seconds['patches']:.1f} s, image {seconds['image']:.1f} s, "
        f"ratio {seconds['patches'] / seconds['image']:.1f}x"
    )


if __name__ == "__main__":
    main()

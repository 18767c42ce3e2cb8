"""End to end on a user's grid map (issue 18): a generated 256 x 256 MovingAI-style maze
(corridors 16 cells wide, imported with the rectangle cover: more boxes than the kernels
unroll, so the broad phase runs) through scripts/train_all.py at tiny sizes."""

import json
from pathlib import Path

import numpy as np

from ntq_jax import grid_maps, make_env
from ntq_jax.planners import visgraph

ROOT = Path(__file__).resolve().parents[1]


def test_maze_through_train_all(tmp_path, script):
    maze = grid_maps.write_movingai(tmp_path / "maze.map", grid_maps.maze_grid(256, corridor=16))
    env = make_env(maze)
    assert env.grid.shape == (256, 256) and env.world.index is not None
    cfg = tmp_path / "maze.yaml"
    # the ensemble rows: best-of-N only (from the members' saved plans); the ensemble and
    # cascade planners' programs are the tiny_run's and test_ensemble's to compile
    cfg.write_text(f"""task: point
envs: [{maze}]
seed: 0
data: {{k_train: 24, gamma_queries: 2000, gamma_eval: false}}
planner: {{name: astar, resolution: 1.0}}
model: {{hidden: [32, 32]}}
train: {{epochs: 2}}
eval: {{k_test: 8, n_plan: 10, replan_rounds: 2, replan_steps: 6, gamma_queries: 2000,
       ensemble: [best]}}
""")
    out = tmp_path / "run"
    r = script("train_all", "--config", cfg, "--out", out, "--no-progress", "--no-figures")
    assert r.returncode == 0, r.stderr[-2000:]
    res = json.loads((out / "results.json").read_text())
    rows = res["rows"]
    assert rows and all(row["k_test"] == 8 for row in rows)
    slug = f"maze-{env.content_hash()[:8]}"
    assert (out / "data" / slug / "env.json").is_file()
    # the grid A* reference solved test queries on the map's own grid; the visibility-graph
    # optimum only below its obstacle limit
    ref = np.load(out / "eval" / slug / "reference.npz")
    assert (ref["uniform_status"] == 0).any()
    assert ("uniform_opt_costs" in ref.files) == (env.world.num_boxes <= visgraph.MAX_OBSTACLES)

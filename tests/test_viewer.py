"""The 3-D scene figure (ntq_jax.scenes.viewer): every obstacle kind, states, a path, a
collision, the atomic PNG, and its refusals; the scripts' 3-D options (export_env --png,
measure_gamma on a 3-D JSON with --skip-existing). The tiny test arm keeps it quick."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from script_loader import load_script

import ntq_jax as nj
from ntq_jax.scenes import viewer

DATA = Path(__file__).resolve().parent / "data"


@pytest.fixture(scope="module")
def env():
    return nj.envs.Env.from_json(
        {
            "name": "tiny_scene",
            "robot": {
                "kind": "serial_arm",
                "urdf": str(DATA / "tiny_arm.urdf"),
                "srdf": str(DATA / "tiny_arm.srdf"),
            },
            "bounds": [[-1, 1], [-1, 1], [-0.2, 1]],
            "spheres": [[0.3, 0.3, 0.3, 0.08]],
            "cuboids": [
                {
                    "center": [0.4, -0.1, 0.4],
                    "half_extents": [0.1, 0.05, 0.08],
                    "quat_xyzw": [0, 0, 0.3826834, 0.9238795],
                }
            ],
            "capsules": [[-0.3, 0.2, 0.0, -0.3, 0.2, 0.5, 0.05]],
            "padding": 0.0,
            "query": [[0, 0, 0, 0], [1.0, 0.5, 0.1, 0.3]],
        }
    )


def test_scene_figure_with_states_path_and_a_collision(env, tmp_path):
    notes, bars = [], []

    class Bar:
        def __init__(self, **kw):
            self.n, self.total = 0, kw["total"]
            bars.append(self)

        def update(self, n=1):
            self.n += n

        def set_postfix_str(self, s):
            pass

        def close(self):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            pass

    path = np.array([[0, 0, 0, 0], [0.5, 0.8, 0.05, 0.0], [1.0, 0.5, 0.1, 0.3]])
    fig = viewer.draw_scene(
        env, path=path, path_states=5, log=notes.append, progress=lambda **kw: Bar(**kw)
    )
    assert bars[0].n == bars[0].total == 2 + 3  # start, goal and 3 faded path states
    assert len(notes) == 1 and "faces" in notes[0]
    ax = fig.axes[0]
    spans = [np.diff(getattr(ax, f"get_{a}lim")())[0] for a in "xyz"]
    assert np.allclose(spans, spans[0])  # equal scaling
    assert ax.get_xlabel() == "x (m)" and ax.get_title() == "tiny_scene"
    out = viewer.save(fig, tmp_path / "figs" / "scene.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 5000
    assert [p.name for p in out.parent.iterdir()] == ["scene.png"]  # no temporary left

    # a state whose base sphere sits in the capsule: its spheres are marked
    inside = np.array([0.0, 0.0, 0.0, 0.0])
    moved = env.to_json() | {"capsules": [[0.0, 0.0, 0.0, 0.0, 0.0, 0.3, 0.05]]}
    hit_env = nj.envs.Env.from_json(moved)
    notes.clear()
    fig = viewer.draw_scene(
        hit_env, states=inside, labels=["inside"], limits="bounds", view=(30, -60), log=notes.append
    )
    assert not bool(hit_env.is_valid(inside[None])[0])
    assert any(
        t.get_text() == "sphere touching an obstacle" for t in fig.axes[0].get_legend().get_texts()
    )
    viewer.save(fig, tmp_path / "hit.png")


def test_scene_figure_refusals(env):
    with pytest.raises(ValueError, match="planar map"):
        viewer.draw_scene(nj.make_env("point/0"))
    with pytest.raises(ValueError, match=r"\(k, 4\)"):
        viewer.draw_scene(env, states=np.zeros((2, 7)))
    with pytest.raises(ValueError, match="non-finite"):
        viewer.draw_scene(env, states=[[0, np.nan, 0, 0]])
    with pytest.raises(ValueError, match="labels"):
        viewer.draw_scene(env, labels=["only one"])
    with pytest.raises(ValueError, match="limits"):
        viewer.draw_scene(env, limits=[[0, 1]])


def test_export_png_and_gamma_of_a_3d_json(env, tmp_path, capsys):
    scene = tmp_path / "scene.json"
    env.save_json(scene)
    export = load_script("export_env", "_viewer_export_env")
    png = tmp_path / "scene.png"
    assert export.main([str(scene), "--png", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert export.main(["point/0", "--png", str(tmp_path / "p.png")]) == 2
    assert "planar" in capsys.readouterr().err and not (tmp_path / "p.png").exists()

    gamma = load_script("measure_gamma", "_viewer_measure_gamma")
    out = tmp_path / "gamma.json"
    argv = ["--env", str(scene), "--queries", "200", "--json", str(out), "--no-progress"]
    assert gamma.main(argv) == 0
    first = json.loads(out.read_text())
    assert first["queries"] == 200 and first["chunk"] == gamma.ARM3D_CHUNK
    assert first["check"] == "discretized" and first["resolution"] == 1 / 32
    assert "this one problem" in first["world"]
    capsys.readouterr()
    stamp = out.stat().st_mtime_ns
    assert gamma.main(argv + ["--skip-existing"]) == 0
    assert "already holds this measurement" in capsys.readouterr().out
    assert out.stat().st_mtime_ns == stamp  # not measured, not written again
    assert gamma.main(argv[:3] + ["201"] + argv[4:] + ["--skip-existing"]) == 0
    assert json.loads(out.read_text())["queries"] == 201  # another measurement: made

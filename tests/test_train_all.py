"""End to end: the pipeline (ntq_jax.experiment.pipeline) on a tiny config (data -> train -> evaluate ->
report), its resume, the refusal of a foreign run folder (also through scripts/train_all.py:
one error line, exit code 2), and scripts/plan.py's input errors.

Every success in the saved paths files is re-checked with shapely (float64, closed
boxes), independently of the planner's flag and of the package's kernels.
"""

import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import TINY_RUN
from shapely.geometry import LineString, Point
from shapely.geometry import box as shapely_box
from shapely.ops import unary_union

from ntq_jax import make_env
from ntq_jax.experiment.pipeline import PipelineError, load_config, prepare_run, run_pipeline

ROOT = Path(__file__).resolve().parents[1]
TINY = TINY_RUN  # the suite's tiny point/2 run (conftest.py)


def _script(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _pipeline(out, extra=(), log=print):
    cfg = load_config(None, list(TINY) + list(extra))
    return run_pipeline(cfg, prepare_run(cfg, out), progress=False, log=log)


@pytest.fixture(scope="module")
def run(tiny_run, tmp_path_factory):
    """A copy of the session's finished tiny run (conftest.py: ``_pipeline`` of TINY, shared
    with test_golden and test_bad_inputs); the tests here rerun and reuse their copy."""
    assert tiny_run.config == TINY
    assert tiny_run.written["tables.md"] == tiny_run.path / "tables.md"
    out = tmp_path_factory.mktemp("run") / "run"
    shutil.copytree(tiny_run.path, out)
    return out


def test_run_folder_contents(run):
    res = json.loads((run / "results.json").read_text())
    rows = res["rows"]
    assert {(r["model"], r["query_kind"]) for r in rows} == {
        (m, k)
        for m in [f"PNet_{m}" for m in range(4)] + ["PNet_ens", "PNet_best-of-4", "PNet_cascade"]
        for k in ("uniform", "nontrivial")
    }
    for r in rows:
        assert r["k_test"] == 16 and 0 <= r["success_ratio"] <= 1
        lo, hi = r["success_ci95"]
        assert lo <= r["success_ratio"] <= hi
        assert r["gamma_nt"] is not None
        # in band / out of band: a partition of the test queries and of the successes
        assert r["band_padding"] == 0.8 and r["n_in_band"] + r["n_out_band"] == 16
        assert r["successes_in_band"] + r["successes_out_band"] == r["successes"]
    queries = np.load(run / "eval" / "point_2" / "queries.npz")
    env = make_env("point/2")
    for kind in ("uniform", "nontrivial"):
        q = queries[kind]
        band = np.asarray(env.is_valid(q.reshape(-1, 2), padding=0.8)).reshape(-1, 2).all(axis=1)
        assert {r["n_in_band"] for r in rows if r["query_kind"] == kind} == {int(band.sum())}
    md = (run / "tables.md").read_text()
    assert "## Point robot planning" in md and "Environment point/2, gamma_nt" in md
    assert "data planner: astar; reference planner: astar" in md
    assert all(r["data_planner"] == "astar" for r in rows)
    for m in range(4):
        assert f"| PNet_{m} |" in md
    assert (run / "tables.tex").read_text().count("\\begin{tabular}") == 2  # results, comparisons
    assert (
        len((run / "results.csv").read_text().strip().splitlines()) == 1 + 2 * 7
    )  # header + (4 members + 3 ensemble rows) x 2 query kinds
    for f in ("success_ratio.png", "examples_point_2.png", "queries_point_2.png"):
        assert (run / "figures" / f).stat().st_size > 1000
    assert (run / "data" / "point_2" / "env.json").is_file()
    assert (run / "models" / "point_2" / "ensemble" / "ensemble.json").is_file()
    info = json.loads((run / "run.json").read_text())
    assert {"data/point_2", "train/point_2", "eval/point_2", "report"} <= set(info["stages"])


def test_every_success_is_collision_free(run):
    env = json.loads((run / "data" / "point_2" / "env.json").read_text())
    obst = unary_union(
        [shapely_box(cx - hw, cy - hh, cx + hw, cy + hh) for cx, cy, hw, hh in env["boxes"]]
    )
    (x0, x1), (y0, y1) = env["bounds"]
    checked = 0
    for f in sorted((run / "paths" / "point_2").glob("PNet_*_*.npz")):
        z = np.load(f)
        assert z["paths"].shape[0] == 16 and np.all(np.isinf(z["costs"][~z["success"]]))
        for i in np.flatnonzero(z["success"]):
            p = z["paths"][i, : z["lengths"][i]].astype(np.float64)
            np.testing.assert_allclose(p[0], z["queries"][i, 0], atol=1e-6)
            np.testing.assert_allclose(p[-1], z["queries"][i, 1], atol=1e-6)
            assert np.all((p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1))
            for a, b in zip(p[:-1], p[1:]):
                geom = Point(a) if np.allclose(a, b) else LineString([a, b])
                assert not geom.intersects(obst), (f.name, i)
            seg = np.linalg.norm(np.diff(p, axis=0), axis=1).sum()
            assert z["costs"][i] == pytest.approx(seg, rel=1e-4)
            checked += 1
    assert (
        len(list((run / "paths" / "point_2").glob("*.npz"))) == 7 * 2 + 1
    )  # (4 members + 3 ensemble rows) x 2 kinds + validation.npz
    assert checked > 0


def test_ensemble_rows(run):
    """PNet_ens, PNet_best-of-4 and PNet_cascade: rows in every output, measured like the
    members."""
    rows = json.loads((run / "results.json").read_text())["rows"]
    by = {(r["model"], r["query_kind"]): r for r in rows}
    keys = set(by[("PNet_0", "uniform")])
    md = (run / "tables.md").read_text()
    tex = (run / "tables.tex").read_text()
    csv_models = [ln.split(",")[2] for ln in (run / "results.csv").read_text().splitlines()[1:]]
    for name in ("PNet_ens", "PNet_best-of-4", "PNet_cascade"):
        assert f"| {name} |" in md and csv_models.count(name) == 2
        for kind in ("uniform", "nontrivial"):
            r = by[(name, kind)]
            assert set(r) == keys and r["member"] is None and r["dataset"] is None
            assert r["k_test"] == 16 and r["seconds_per_query"] > 0
            z = np.load(run / r["paths_file"])
            assert r["paths_file"] == f"paths/point_2/{name}_{kind}.npz"
            np.testing.assert_array_equal(
                z["queries"], np.load(run / by[("PNet_0", kind)]["paths_file"])["queries"]
            )
            assert int(z["success"].sum()) == r["successes"]
    assert "$\\mathsf{PNet}_\\mathsf{ens}$" in tex
    assert "$\\mathsf{PNet}_\\mathsf{best\\mbox{-}of\\mbox{-}4}$" in tex
    assert (
        md.index("| PNet_3 |")
        < md.index("| PNet_ens |")
        < md.index("| PNet_best-of-4 |")
        < md.index("| PNet_cascade |")
    )
    for kind in ("uniform", "nontrivial"):  # best-of-4 from the members' saved plans
        best = np.load(run / by[("PNet_best-of-4", kind)]["paths_file"])
        members = [np.load(run / by[(f"PNet_{m}", kind)]["paths_file"]) for m in range(4)]
        ok = np.stack([z["success"] for z in members])
        np.testing.assert_array_equal(best["success"], ok.any(axis=0))
        costs = np.stack([np.where(z["success"], z["costs"], np.inf) for z in members])
        np.testing.assert_array_equal(best["costs"], costs.min(axis=0))
        assert float(best["seconds"]) == pytest.approx(sum(float(z["seconds"]) for z in members))
        # the cascade: members in the order of their validation success, each query's
        # first success; every member's failures are somebody's fallback
        val = np.load(run / "paths" / "point_2" / "validation.npz")
        order = [int(m) for m in val["order"]]
        assert sorted(order) == [0, 1, 2, 3]
        assert list(val["success"][order]) == sorted(val["success"], reverse=True)
        cas = np.load(run / by[("PNet_cascade", kind)]["paths_file"])
        np.testing.assert_array_equal(cas["order"], order)
        first = cas["member"] == order[0]
        assert first[cas["success"]].mean() >= 0.5  # the first member solves most of them
        assert set(np.unique(cas["member"][cas["success"]])) <= set(order)


def test_rerun_resumes_without_redoing_work(run):
    files = sorted((run / "paths").rglob("*.npz")) + [run / "eval" / "point_2" / "reference.npz"]
    before = {f: f.stat().st_mtime_ns for f in files}
    lines = []
    _pipeline(run, log=lines.append)
    assert {f: f.stat().st_mtime_ns for f in files} == before
    assert any("train: complete" in ln for ln in lines)
    assert "| PNet_3 |" in (run / "tables.md").read_text()


def test_foreign_run_folder_is_refused(run):
    with pytest.raises(PipelineError, match="another config"):
        _pipeline(run, ["eval.k_test=17"])


def test_train_all_script_error_is_one_line(run):
    """The command line turns the refusal into one error line and exit code 2, no traceback."""
    args = [
        sys.executable,
        str(ROOT / "scripts" / "train_all.py"),
        "--out",
        str(run),
        "--no-progress",
    ] + sum((["--set", s] for s in TINY + ["eval.k_test=17"]), [])
    proc = subprocess.run(args, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "another config" in err[0]
    assert "Traceback" not in proc.stderr


def test_plan_script_rejects_bad_states(run, capsys):
    plan = _script("plan")
    env = json.loads((run / "data" / "point_2" / "env.json").read_text())
    cx, cy = env["boxes"][0][:2]  # inside the first wall
    assert (
        plan.main(
            ["--run", str(run), "--model", "0", "--start", str(cx), str(cy), "--goal", "1", "1"]
        )
        == 2
    )
    assert "--start" in capsys.readouterr().err
    assert (
        plan.main(["--run", str(run), "--model", "0", "--start", "1", "1", "--goal", "30", "1"])
        == 2
    )
    assert "out of bounds" in capsys.readouterr().err
    assert (
        plan.main(["--run", str(run), "--model", "9", "--start", "1", "1", "--goal", "2", "2"]) == 2
    )
    assert "--model" in capsys.readouterr().err


def test_report_has_paired_comparisons(run):
    """PNet_1..3 vs PNet_0 and the ensemble rows vs the best member, per query kind,
    recomputed here from the saved paths files."""
    from ntq_jax.stats import paired_comparison

    md = (run / "tables.md").read_text()
    rows = json.loads((run / "results.json").read_text())["rows"]
    comps = json.loads((run / "results.json").read_text())["comparisons"]
    best = {
        k: max(
            range(4),
            key=lambda m: (
                next(
                    r["successes"]
                    for r in rows
                    if r["model"] == f"PNet_{m}" and r["query_kind"] == k
                ),
                -m,
            ),
        )
        for k in ("uniform", "nontrivial")
    }
    assert {(c["model"], c["baseline"], c["query_kind"]) for c in comps} == {
        (f"PNet_{m}", "PNet_0", k) for m in (1, 2, 3) for k in ("uniform", "nontrivial")
    } | {
        (m, f"PNet_{best[k]}", k)
        for m in ("PNet_ens", "PNet_best-of-4", "PNet_cascade")
        for k in ("uniform", "nontrivial")
    }
    for c in comps:
        base = c["baseline"] + (" (best member)" if c["baseline_rule"] else "")
        assert f"| {c['model']} | {base} | {c['query_kind']} | {c['both']} / {c['only_a']} / " in md
        files = [
            run / "paths" / "point_2" / f"{m}_{c['query_kind']}.npz"
            for m in (c["model"], c["baseline"])
        ]
        want = paired_comparison(*(dict(np.load(f)) for f in files))
        assert c["n"] == 16 and c["mcnemar_p"] == pytest.approx(want["mcnemar_p"])
        assert c["success_diff"] == pytest.approx(want["success_diff"])
        assert c["cost_n"] == want["cost_n"]
    # the LaTeX report has them too: one comparison table, a line per comparison
    tex = (run / "tables.tex").read_text()
    assert tex.count("paired comparisons on the same test queries") == 1
    body = tex[tex.index("paired comparisons on the same test queries") :]
    lines = [ln for ln in body.splitlines() if ln.strip().startswith("point/2 & ")]
    assert len(lines) == len(comps)
    c = next(c for c in comps if c["model"] == "PNet_3" and c["query_kind"] == "nontrivial")
    diff = f"{c['success_diff']:.3f} [{c['success_diff_ci95'][0]:.3f}, "
    assert any(
        "$\\mathsf{PNet}_3$ & $\\mathsf{PNet}_0$ & non-trivial & " + diff in ln for ln in lines
    )


def test_headline_reads_each_maps_success_and_the_gap_from_results_json(run):
    from ntq_jax.experiment.headline import headline

    res = json.loads((run / "results.json").read_text())
    lines = headline(run)
    text = "\n".join(lines)
    for env in {r["env"] for r in res["rows"]}:
        assert f"{env}: success ratio with steerTo" in text
    r = next(r for r in res["rows"] if r["model"] == "PNet_3" and r["query_kind"] == "nontrivial")
    row = next(line for line in lines if line.strip().startswith("PNet_3 "))
    assert row.split()[-1] == f"{r['success_ratio']:.3f}"  # the non-trivial column
    c = next(
        c
        for c in res["comparisons"]
        if c["model"] == "PNet_3" and c["baseline"] == "PNet_0" and c["query_kind"] == "nontrivial"
    )
    assert f"PNet_3 - PNet_0, non-trivial: {c['success_diff']:+.3f}" in text
    assert lines[-1].startswith("full tables:") or lines[-1].startswith("figures:")
    assert headline(run / "missing") == []

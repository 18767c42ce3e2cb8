"""Per-query outcomes a summary keeps (ntq_jax.experiment.outcomes): written from a run
folder's paths files, loaded back, every count of the summary recomputed from them, and
the command line that does it over a results folder. (A real run's outcomes, written by
write_summary: tests/test_reproduce_script.py.)"""

import json

import numpy as np

from ntq_jax.experiment import outcomes as O
from ntq_jax.experiment.metrics import metrics


def _run_folder(root, k=40, seed=0):
    """A finished run's files for one map: results.json rows and their paths files."""
    rng = np.random.default_rng(seed)
    slug = "point_0"
    (root / "eval" / slug).mkdir(parents=True)
    (root / "paths" / slug).mkdir(parents=True)
    queries = {kind: rng.random((k, 2, 2)).astype(np.float32) for kind in O.KINDS}
    np.savez(root / "eval" / slug / "queries.npz", **queries)
    rows = []
    for kind in O.KINDS:
        ref_costs = rng.uniform(1, 2, k)
        ref_status = (rng.random(k) < 0.05).astype(np.int8)
        for m in ("PNet_0", "PNet_1", "PNet_ens"):
            success = rng.random(k) < 0.7
            costs = np.where(success, ref_costs * rng.uniform(1, 1.2, k), np.inf)
            cause = np.where(success, 0, rng.integers(1, 4, k)).astype(np.uint8)
            f = f"paths/{slug}/{m}_{kind}.npz"
            np.savez(
                root / f,
                success=success,
                costs=costs,
                cause=cause,
                ref_costs=ref_costs,
                ref_status=ref_status,
            )
            row = {
                "env": "point/0",
                "env_slug": slug,
                "model": m,
                "query_kind": kind,
                "steer": True,
                "paths_file": f,
            }
            row.update(metrics(success, costs, cause, ref_costs, ref_status))
            rows.append(row)
    (root / "results.json").write_text(json.dumps({"rows": rows}))
    return rows


def test_outcomes_recompute_every_count_of_a_summary(tmp_path, capsys):
    from ntq_jax.stats import mcnemar_exact

    run, out = tmp_path / "run", tmp_path / "results" / "point" / "point_0"
    rows = _run_folder(run)
    by = {(r["model"], r["query_kind"]): r for r in rows}
    comps = []
    for kind in O.KINDS:
        a = np.load(run / by[("PNet_1", kind)]["paths_file"])["success"]
        b = np.load(run / by[("PNet_0", kind)]["paths_file"])["success"]
        oa, ob = int((a & ~b).sum()), int((~a & b).sum())
        comps.append(
            {
                "model": "PNet_1",
                "baseline": "PNet_0",
                "query_kind": kind,
                "steer": True,
                "n": len(a),
                "both": int((a & b).sum()),
                "only_a": oa,
                "only_b": ob,
                "neither": int((~a & ~b).sum()),
                "success_diff": (oa - ob) / len(a),
                "mcnemar_p": mcnemar_exact(oa, ob),
            }
        )
    out.mkdir(parents=True)
    (out / "summary.json").write_text(json.dumps({"rows": rows, "comparisons": comps}))
    path = O.write(run, "point/0", out, train_seed=2)
    assert path.stat().st_size < 6000  # 3 models x 2 kinds x 40 queries, compressed
    got = O.load(path)
    assert got["meta"]["train_seed"] == 2 and set(got["meta"]["queries_sha256"]) == set(O.KINDS)
    assert got[("PNet_0", "uniform", True)]["success"].dtype == bool
    n, bad = O.recount(out)
    assert bad == [] and n == 6 * 6 + 2 * 7  # rows: 6 numbers each; comparisons: 7 each
    # a count that does not match its outcomes is named
    summary = json.loads((out / "summary.json").read_text())
    summary["rows"][0]["successes"] += 1
    summary["comparisons"][1]["only_a"] += 1
    (out / "summary.json").write_text(json.dumps(summary))
    _, bad = O.recount(out)
    assert len(bad) == 2 and "PNet_0 uniform successes" in bad[0] and "only_a" in bad[1]
    # the command line: recount under a root, list the summaries without outcomes
    (tmp_path / "results" / "point" / "point_1").mkdir()
    (tmp_path / "results" / "point" / "point_1" / "summary.json").write_text("{}")
    assert O.main([str(tmp_path / "results")]) == 1
    text = capsys.readouterr().out
    assert "1 summaries with outcomes" in text and "2 mismatches" in text and "point_1" in text

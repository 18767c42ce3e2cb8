"""scripts/factor_study.py: its cells and their configs (no cell is run here)."""

from __future__ import annotations

from pathlib import Path

from script_loader import load_script

ROOT = Path(__file__).resolve().parent.parent


def _script():
    return load_script("factor_study")


def test_every_cell_has_a_config_that_varies_one_factor(monkeypatch):
    monkeypatch.chdir(ROOT)  # the cells read configs/<task>.yaml
    fs = _script()
    cells = fs.cells()
    assert len({c.key for c in cells}) == len(cells)
    # the point maps' dense data modes are queued late, then their 100-epoch checks, then
    # nlink/4's BIT* data with training seeds 1 and 2, then training seeds 3 and 4 of the
    # maps whose three seeds left the verdict open
    tail = [c for c in cells if fs.task_of(c.map) == "point" and c.data in fs.COSTLY]
    checks = [fs.Cell(m, "density" + fs.FULL_EPOCHS, "ours") for m in ("point/0", "point/3")]
    bitstar = [fs.Cell("nlink/4", "bitstar", "ours", k) for k in (1, 2)]
    assert fs.Cell("nlink/4", "bitstar", "ours") in cells
    more = [c for c in cells if c.train_seed in fs.EXTRA_SEEDS]
    assert {(c.map, c.train_seed) for c in more} == {(m, k) for m in fs.MORE_SEEDS for k in (3, 4)}
    assert all(c.data == fs.default_data(c.map) and c.budget == "ours" for c in more)
    got = cells[-len(tail) - 4 - len(more) :]
    assert tail and got == tail + checks + bitstar + more
    from ntq_jax.experiment.paper import MAPS as PAPER_MAPS

    # every map of Tables I-IV is re-run by the queue (its default cell)
    assert {
        c.map
        for c in cells
        if c.data == fs.default_data(c.map) and c.budget == "ours" and not c.train_seed
    } == set(PAPER_MAPS)
    for c in cells:
        cfg, sets = fs.cell_config(c)
        assert list(cfg.envs) == [c.map]
        base, _ = fs.cell_config(fs.Cell(c.map, fs.default_data(c.map), "ours"))
        if c.data.endswith(fs.KEEP_LAST):
            ds = cfg.data.datasets
            assert [d.prune for d in ds] == [False, False, False, True, "keep_last"]
            assert [d.p_nt for d in ds] == [0.0, 0.5, 1.0, 1.0, 1.0]
            # the same data paths, planner and training as the default cell: only D4 is added
            assert cfg.planner == base.planner and cfg.train == base.train
        # the data mode the cell names is the one its map's data planner gets (a task
        # config's per-map data_paths must not override it)
        mode = c.data
        for suffix in (fs.KEEP_LAST, fs.FULL_EPOCHS):
            mode = mode[: -len(suffix)] if mode.endswith(suffix) else mode
        got = cfg.planner.data_paths_for(c.map)
        if mode in ("shortcut", "raw"):
            assert got == mode, (c.key, got)
        elif mode == "density":
            assert isinstance(got, float) and got > 0, (c.key, got)
        else:  # bitstar: the roadmap's raw paths stand in, replaced by the committed record
            assert mode == "bitstar" and got == "raw" and cfg.data.per_env, (c.key, got)
        if c.train_seed:  # the same data as the cell's seed 0
            same, _ = fs.cell_config(fs.Cell(c.map, c.data, "ours"))
            assert cfg.train.seed == c.train_seed and cfg.data == same.data
            assert cfg.planner == same.planner
        # the point maps' dense cells train fewer epochs (more optimizer steps than the
        # default's 100 epochs); every other cell trains the task config's epochs
        costly = (
            fs.task_of(c.map) == "point"
            and mode in fs.COSTLY
            and not c.data.endswith(fs.FULL_EPOCHS)
        )
        assert cfg.train.epochs == (fs.COSTLY_EPOCHS if costly else base.train.epochs), c.key
        if c.data.endswith(fs.FULL_EPOCHS):  # the same data as the 10-epoch cell
            short, _ = fs.cell_config(fs.Cell(c.map, mode, "ours"))
            assert cfg.data == short.data and cfg.planner == short.planner
            assert cfg.train.epochs == 100 and short.train.epochs == fs.COSTLY_EPOCHS
        if c.budget != "ours":
            assert cfg.data == base.data and cfg.eval != base.eval


def test_next_workers_claim_distinct_cells(tmp_path):
    """Two ``--next`` workers never run the same cell: a claimed cell is skipped by the other."""
    import subprocess
    import sys

    fs = _script()
    cell = fs.cells()[0]
    code = (
        "import importlib.util,sys; from pathlib import Path\n"
        f"spec = importlib.util.spec_from_file_location('fs', {str(ROOT / 'scripts/factor_study.py')!r})\n"
        "fs = importlib.util.module_from_spec(spec); spec.loader.exec_module(fs)\n"
        f"print(fs.claim(fs.cells()[0], Path({str(tmp_path)!r})), flush=True); sys.stdin.read()"
    )
    p = subprocess.Popen(
        [sys.executable, "-c", code],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    try:
        assert p.stdout.readline().strip() == "True"
        assert not fs.claim(cell, tmp_path)  # held by the other worker
        assert fs.claim(fs.cells()[1], tmp_path)
        listed = _list(fs, tmp_path, tmp_path / "results")
        assert listed[cell.key].startswith(f"running {cell.key}  (claimed by pid {p.pid} on ")
        assert listed[fs.cells()[2].key].startswith("pending")
    finally:
        p.stdin.close()
        p.wait()
    assert fs.claim(cell, tmp_path)  # released when the worker ended


def test_next_claims_only_the_cell_it_runs(tmp_path, monkeypatch):
    """``--next`` claims one cell, not every pending one (claims last until the process exits,
    so claiming all would leave the other workers nothing to run)."""
    fs = _script()
    claimed = []
    real = fs.claim
    monkeypatch.setattr(fs, "ready", lambda c: None)
    monkeypatch.setattr(fs, "claim", lambda c, runs: claimed.append(c) or real(c, runs))
    cells = fs.cells()
    first = fs.next_cell(cells, tmp_path / "results", tmp_path / "runs")
    assert first == [cells[0]] and claimed == [cells[0]]


def _list(fs, runs, results) -> dict[str, str]:
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert fs.main(["--list", "--runs", str(runs), "--results", str(results)]) == 0
    return {line.split()[1]: line for line in buf.getvalue().splitlines()}


def test_a_damaged_cell_is_pending_redone_first_and_stops_a_report_with_one_line(
    tmp_path, monkeypatch, capsys
):
    """A corrupt paired.json or summary.json: --list shows the cell pending (naming the
    file), --next redoes it first, and a report says so in one line instead of a traceback."""
    import json

    fs = _script()
    cells, results = fs.cells(), tmp_path / "results"
    good = {"cell": cells[0]._asdict(), "paired": []}
    for c, paired, summary in (
        (cells[0], json.dumps(good), "{}"),
        (cells[3], json.dumps(good), '{"env": '),
        (cells[4], '{"cell": {"map"', None),
    ):
        (results / c.key).mkdir(parents=True)
        (results / c.key / "paired.json").write_text(paired)
        if summary is not None:
            (results / c.key / "summary.json").write_text(summary)
    listed = _list(fs, tmp_path / "runs", results)
    assert listed[cells[0].key].startswith("done")
    for c, name in ((cells[3], "summary.json"), (cells[4], "paired.json")):
        assert listed[c.key].startswith("pending") and str(results / c.key / name) in listed[c.key]
    monkeypatch.setattr(fs, "ready", lambda c: None)
    assert fs.next_cell(cells, results, tmp_path / "runs") == [cells[3]]
    capsys.readouterr()
    assert fs.main(["--report-only", "--results", str(results)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(results / cells[3].key / "summary.json") in err[0], err
    assert f"--cell {cells[3].key}" in err[0] and not (results / "README.md").exists()


def test_report_shows_each_p_with_its_benjamini_hochberg_q(tmp_path):
    """The main table of README.md: every comparison's McNemar p and its BH q over the study."""
    import json

    from ntq_jax.experiment import factor_table as F

    fs = _script()
    for data, p in (("shortcut", 2e-5), ("bitstar", 0.03)):
        folder = tmp_path / "rigid_0" / data / "ours"
        folder.mkdir(parents=True)
        rows = [
            {
                "model": "PNet_3",
                "baseline": "PNet_0",
                "query_kind": "nontrivial",
                "steer": True,
                "band": b,
                "n": 100,
                "success": 0.6,
                "baseline_success": 0.5,
                "success_diff": 0.1,
                "success_diff_ci95": [0.05, 0.15],
                "mcnemar_p": p,
            }
            for b in F.BANDS
        ]
        cell = {"map": "rigid/0", "data": data, "budget": "ours", "train_seed": 0}
        (folder / "paired.json").write_text(json.dumps({"cell": cell, "sets": [], "paired": rows}))
    text = fs.report(tmp_path).read_text()
    row = next(line for line in text.splitlines() if line.startswith("| rigid/0 | bitstar |"))
    assert row.count("p=0.030 q=0.030 (n=100)") == 3  # 3 of 6 comparisons at p 0.03: q = 0.03
    assert "Benjamini-Hochberg q" in text

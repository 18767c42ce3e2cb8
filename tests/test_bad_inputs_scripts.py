"""Hostile inputs, the scripts' command lines: measure_gamma.py and plan.py arguments and output
files, expected and unexpected errors, unwritable output folders.

Every expected failure is one clear error, nothing is written where it must not be
(split from tests/test_bad_inputs.py by the surface each test probes; the shared
helpers are in bad_inputs_common.py).
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from bad_inputs_common import ROOT, _env, _files, _listing, _one_error_line, _script


@pytest.mark.parametrize(
    "case",
    [
        "gen_unknown_env",
        "gen_missing_config",
        "gen_out_is_file",
        "train_no_env_json",
        "train_cpu_devices_0",
        "export_unknown_env",
        "export_out_under_file",
        "export_no_name",
    ],
)
def test_script_expected_errors_are_one_line(tmp_path, capsys, case):
    afile = tmp_path / "afile"
    afile.write_text("keep")
    script, args, words = {
        "gen_unknown_env": (
            "generate_data",
            ["--env", "point/9", "--out", str(tmp_path / "d")],
            ["point/9"],
        ),
        "gen_missing_config": (
            "generate_data",
            ["--config", str(tmp_path / "no.yaml")],
            ["no.yaml", "not found"],
        ),
        "gen_out_is_file": (
            "generate_data",
            ["--env", "point/0", "--out", str(afile)],
            ["afile", "folder"],
        ),
        "train_no_env_json": (
            "train",
            ["--data", str(tmp_path), "--out", str(tmp_path / "o")],
            ["--data", "env.json"],
        ),
        "train_cpu_devices_0": (
            "train",
            ["--data", str(tmp_path), "--cpu-devices", "0"],
            ["--cpu-devices 0"],
        ),
        "export_unknown_env": ("export_env", ["point/9"], ["point/9"]),
        "export_out_under_file": (
            "export_env",
            ["point/0", "--out", str(afile / "x.json")],
            ["afile", "folder"],
        ),
        "export_no_name": ("export_env", [], ["preset name"]),
    }[case]
    before = _listing(tmp_path)
    assert _script(script).main(args) == 2
    line = _one_error_line(capsys.readouterr().err)
    for w in words:
        assert w in line, (w, line)
    assert _listing(tmp_path) == before


def test_script_unexpected_errors_keep_their_traceback():
    from ntq_jax.experiment.cli import run_cli

    def bug():
        raise KeyError("a bug")

    with pytest.raises(KeyError):
        run_cli(bug)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--padding", "nan"], "argument --padding: must be a finite number >= 0, got 'nan'"),
        (["--padding", "-1"], "argument --padding: must be a finite number >= 0"),
        (["--queries", "1e20"], "argument --queries: must be at most 1e+15, got '1e20'"),
        (["--queries", "2.5"], "argument --queries: must be a whole number >= 1"),
        (["--chunk", "1e12"], "argument --chunk: must be at most"),
        (["--max-hours", "0"], "argument --max-hours: must be a number of hours > 0"),
        (["--seed=-1"], "argument --seed: must be in [0, 4294967295], got -1"),
        (["--seed", str(2**64)], "argument --seed: must be in [0, 4294967295]"),
    ],
)
def test_gamma_script_bad_arguments(tmp_path, capsys, argv, message):
    mg = _script("measure_gamma")
    out = tmp_path / "gamma.json"
    with pytest.raises(SystemExit) as e:
        mg.main(argv + ["--json", str(out), "--no-progress"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not out.exists()


def test_gamma_script_json_unwritable_is_checked_first(tmp_path, capsys):
    mg = _script("measure_gamma")
    (tmp_path / "a_file").write_text("x")
    before = _files(tmp_path)
    for target, message in [
        (tmp_path / "a_file" / "gamma.json", "is a file, not a folder"),
        (tmp_path, "is a folder; give a file name"),
    ]:
        t0 = time.perf_counter()
        assert (
            mg.main(
                ["--queries", "1e12", "--max-hours", "inf", "--no-progress", "--json", str(target)]
            )
            == 2
        )
        captured = capsys.readouterr()
        lines = captured.err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: --json") and message in lines[0]
        assert captured.out == ""  # no estimate: nothing was measured
        assert time.perf_counter() - t0 < 30  # 1e12 queries would take hours
    assert _files(tmp_path) == before


def test_gamma_script_refuses_a_run_longer_than_max_hours(tmp_path, capsys):
    mg = _script("measure_gamma")
    out = tmp_path / "gamma.json"
    assert mg.main(["--queries", "1e15", "--no-progress", "--json", str(out)]) == 2
    captured = capsys.readouterr()
    errors = [line for line in captured.err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "--max-hours 24" in errors[0] and " h left" in errors[0]
    assert captured.out == "" and not out.exists() and _files(tmp_path) == set()


def test_gamma_script_ctrl_c_prints_the_estimate_so_far(tmp_path):
    out = tmp_path / "gamma.json"
    # A shell without job control starts a background job (`nohup pytest &`) with SIGINT
    # ignored, and an ignored signal stays ignored in the child; a handled one is reset to
    # the default at exec, so the child's Python turns Ctrl-C into KeyboardInterrupt again
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        proc = subprocess.Popen(
            [
                sys.executable,
                str(ROOT / "scripts" / "measure_gamma.py"),
                "--queries",
                "1e12",
                "--max-hours",
                "inf",
                "--no-progress",
                "--json",
                str(out),
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=_env(),
        )
    finally:
        signal.signal(signal.SIGINT, before)
    try:
        first = proc.stderr.readline()  # the time estimate: streaming has started
        assert "queries/s: about" in first
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr
    assert "interrupted after" in stdout and "of 1,000,000,000,000 queries" in stdout
    gamma = [line for line in stdout.splitlines() if line.startswith("gamma_nt = ")]
    assert len(gamma) == 1
    value = float(gamma[0].split()[2])
    lo, hi = (float(v) for v in gamma[0].split("[")[1].rstrip("]").split(","))
    assert lo <= value <= hi and hi - lo < 0.01  # point/0 gamma_nt ~0.31, >= 1e6 queries counted
    assert "not written (interrupted)" in stderr and not out.exists()


@pytest.fixture()
def bare_run(tmp_path):
    """A run folder with a config and no models: enough for plan.py's checks before loading."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yaml").write_text("envs: [point/2]\n")
    return run


def test_plan_script_png_unwritable_is_checked_first(bare_run, tmp_path, capsys):
    plan = _script("plan")
    (tmp_path / "a_file").write_text("x")
    before = _files(tmp_path)
    for png, message in [
        (tmp_path / "a_file" / "fig.png", "is a file, not a folder"),
        (tmp_path, "is a folder; give a file name"),
    ]:
        assert (
            plan.main(
                [
                    "--run",
                    str(bare_run),
                    "--model",
                    "0",
                    "--start",
                    "1",
                    "1",
                    "--goal",
                    "2",
                    "2",
                    "--png",
                    str(png),
                    "--no-compile-cache",
                ]
            )
            == 2
        )
        captured = capsys.readouterr()
        lines = captured.err.strip().splitlines()
        # the --png error, not the missing models: the check comes before any loading
        assert len(lines) == 1 and lines[0].startswith("error: --png") and message in lines[0]
        assert captured.out == ""
    assert _files(tmp_path) == before


def test_plan_script_takes_pnet_names_and_checks_the_figure_format_first(
    bare_run, tmp_path, capsys
):
    plan = _script("plan")
    assert plan._model("PNet_3") == plan._model("3") == 3
    assert (
        plan.main(
            [
                "--run",
                str(bare_run),
                "--model",
                "PNet_0",
                "--start",
                "1",
                "1",
                "--goal",
                "2",
                "2",
                "--png",
                str(tmp_path / "p.xyz"),
                "--no-compile-cache",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--png" in err[0] and ".png, .pdf" in err[0]
    with pytest.raises(SystemExit):
        plan.main(
            ["--run", str(bare_run), "--model", "PNet_x", "--start", "1", "1", "--goal", "2", "2"]
        )
    assert "expected N or PNet_<N>" in capsys.readouterr().err


def test_plan_script_default_png_checked_after_the_states(bare_run, capsys):
    """With a writable default figure path the script goes on to the models (missing here)."""
    plan = _script("plan")
    assert (
        plan.main(
            [
                "--run",
                str(bare_run),
                "--model",
                "0",
                "--start",
                "1",
                "1",
                "--goal",
                "2",
                "2",
                "--no-compile-cache",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.startswith("error:") and "--png" not in err
    assert not (bare_run / "figures").exists()


def test_api_json_of_gamma_script_round_trip(tmp_path, capsys):
    """A writable --json is written after the work, with the estimate printed."""
    mg = _script("measure_gamma")
    out = tmp_path / "sub" / "gamma.json"
    assert mg.main(["--queries", "2000", "--no-progress", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["queries"] == 2000 and 0 < data["gamma"] < 1
    assert f"gamma_nt = {data['gamma']:.6f}" in capsys.readouterr().out


@pytest.mark.parametrize(
    "script,argv",
    [
        (
            "generate_data",
            ["--env", "point/0", "--no-progress", "--no-compile-cache", "--out", "{out}"],
        ),
        (
            "learning_curve",
            ["--sizes", "5", "--no-progress", "--no-compile-cache", "--out", "{out}"],
        ),
        ("reproduce", ["--report-only", "--results", "{out}"]),
        ("reproduce", ["--config", "configs/point.yaml", "--results", "{out}"]),
        ("reproduce", ["--config", "configs/point.yaml", "--runs", "{out}"]),
    ],
)
def test_scripts_refuse_an_unwritable_output_folder_first(tmp_path, capsys, script, argv):
    mod = _script(script)
    (tmp_path / "a_file").write_text("x")
    before = _files(tmp_path)
    targets = [
        (tmp_path / "a_file" / "sub", "is a file, not a folder"),
        (tmp_path / "a_file", "is a file, not a folder"),
    ]
    if Path("/proc").is_dir():  # a read-only file system: refused even for root
        targets.append((Path("/proc/ntq_jax_out"), "creating a file in /proc failed"))
    for target, message in targets:
        rc = mod.main([a.format(out=target) for a in argv])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1, err
        assert err[0].startswith("error: --") and message in err[0] and "writable" in err[0]
    assert _files(tmp_path) == before

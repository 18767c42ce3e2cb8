"""Ensemble training: vmapped == members alone, loss falls, resume (also after kill -9),
checkpoint errors, load for planning, sharded == unsharded.

Data: straight-line paths between uniform random points of the point/0 workspace,
cut into unit steps (MPNet's rows: (current, goal) -> next). Four datasets of
different sizes, so the per-member epoch masking is exercised.
"""

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import numpy as np
import pytest

from ntq_jax import make_env, models
from ntq_jax import training as T
from ntq_jax.data import straight_line_rows
from ntq_jax.models import ModelConfig
from ntq_jax.training.config import TrainConfig

MODEL = ModelConfig(hidden=(32, 32), dropout=0.1, dropout_layers=1)
TRAIN = TrainConfig(
    epochs=6,
    batch_size=32,
    learning_rate=0.05,
    val_fraction=0.2,
    steps_per_call=4,
    eval_every=4,
    checkpoint_every=16,
)
PATHS = (30, 24, 18, 10)  # paths per dataset: unequal sizes (D3 smallest, as in the paper)
SEED = 3
# A sharded program is partitioned and fused differently from the one-device one; after the
# ~40 steps of TRAIN the weights (magnitude ~0.5) differ by a few float32 ulps times the
# step count (6e-6 observed). Larger differences (a wrong member on a device) are O(0.1).
SHARD_ATOL = 2e-5


def straight_paths(n_paths: int, seed: int, lo=(0.0, 0.0), hi=(20.0, 20.0), step=1.5):
    """Rows of straight paths between random points: inputs (N, 4), targets (N, 2), path ids."""
    return straight_line_rows(seed, lo, hi, step=step, n_paths=n_paths)


@pytest.fixture(scope="module")
def env():
    return make_env("point/0")


@pytest.fixture(scope="module")
def datasets():
    return [straight_paths(n, 100 + i) for i, n in enumerate(PATHS)]


@pytest.fixture(scope="module")
def full_run(env, datasets, tmp_path_factory):
    out = tmp_path_factory.mktemp("full")
    ens, hist = T.train_ensemble(
        datasets, env, MODEL, TRAIN, seed=SEED, ckpt_dir=out, progress=False
    )
    return out, ens, hist


def _assert_trees_close(a, b, rtol=1e-5, atol=1e-6):
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    assert len(la) == len(lb)
    for x, y in zip(la, lb):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=rtol, atol=atol)


def test_split_by_path_never_shares_a_path(datasets):
    x, y, pi = datasets[0]
    tr, va, ntp, nvp = T.split_by_path(pi, 0.2, SEED, 0)
    assert set(pi[tr]).isdisjoint(pi[va])
    assert len(tr) + len(va) == len(pi) and nvp == round(0.2 * PATHS[0]) and ntp + nvp == PATHS[0]
    # rows without path ids: the paths are recovered from the chaining of the rows
    np.testing.assert_array_equal(T.infer_path_index(x, y), pi)
    md = T.prepare_member((x, y), 0.2, SEED, 0)
    assert len(md.train_x) == len(tr) and len(md.val_x) == len(va)


def test_schedule_counts_epochs_per_member():
    sch = T.Schedule(n_train=(100, 64, 10), batch_size=32, epochs=3)
    assert sch.steps_per_epoch == (4, 2, 1) and sch.member_steps == (12, 6, 3)
    assert sch.total_steps == 12
    plan = T.BatchPlan(sch, 0, [0, 1, 2])
    idx, mask, active = plan.chunk(0, 12)
    assert active.sum(0).tolist() == [12, 6, 3]
    for m, n in enumerate(sch.n_train):  # every row exactly `epochs` times, padding masked
        seen = np.bincount(idx[:, m][mask[:, m] > 0], minlength=n)
        assert seen.tolist() == [3] * n


def test_vmapped_step_equals_members_trained_alone(env, datasets, full_run):
    _, ens, hist = full_run
    for m in (0, 3):  # the largest and the smallest dataset (finishes first, then masked)
        alone, h1 = T.train_ensemble(
            [datasets[m]], env, MODEL, TRAIN, seed=SEED, member_ids=[m], progress=False
        )
        _assert_trees_close(
            models.unstack_state(ens.params, m), models.unstack_state(alone.params, 0)
        )
        n = len(h1.step)
        np.testing.assert_allclose(hist.train_loss[1:n, m], h1.train_loss[1:, 0], rtol=1e-5)
        np.testing.assert_allclose(hist.val_loss[:n, m], h1.val_loss[:, 0], rtol=1e-5)
    # and the members really differ from each other
    assert not np.allclose(ens.params["out"]["kernel"][...][0], ens.params["out"]["kernel"][...][3])


def test_loss_falls_and_every_member_does_its_epochs(full_run):
    _, _, hist = full_run
    for m in range(len(PATHS)):
        tl = hist.train_loss[:, m][np.isfinite(hist.train_loss[:, m])]
        vl = hist.val_loss[:, m][np.isfinite(hist.val_loss[:, m])]
        assert tl[-1] < 0.5 * tl[0], (m, tl)
        assert vl[-1] < 0.2 * vl[0], (m, vl)  # vl[0]: before training
        assert np.nanmax(hist.epoch[:, m]) == TRAIN.epochs


def test_history_files(full_run):
    out, _, hist = full_run
    lines = (out / "history.jsonl").read_text().splitlines()
    assert len(lines) == len(hist.step)
    assert json.loads(lines[-1])["step"] == int(hist.step[-1])
    csv = (out / "history.csv").read_text().splitlines()
    assert csv[0] == "step,member,dataset,epoch,train_loss,val_loss"
    rows = np.isfinite(hist.train_loss) | np.isfinite(hist.val_loss)
    assert len(csv) - 1 == int(rows.sum())
    assert hist.step[0] == 0 and np.all(np.isnan(hist.train_loss[0]))  # untrained baseline
    assert (out / "curves.png").stat().st_size > 1000


def test_load_ensemble_for_planning(full_run):
    out, ens, _ = full_run
    loaded = T.load_ensemble(out)
    _assert_trees_close(loaded.params, ens.params, rtol=0, atol=0)
    assert loaded.spec == ens.spec
    c = np.array([[1.0, 1.0], [5.0, 5.0]], np.float32)
    g = np.array([[10.0, 10.0], [15.0, 2.0]], np.float32)
    fn = jax.jit(lambda e, k: models.predictor(e)(k, c, g))  # Ensemble is a pytree
    a, b = fn(loaded, jax.random.key(0)), fn(ens, jax.random.key(0))
    np.testing.assert_allclose(a, b, rtol=1e-6)
    with pytest.raises(T.CheckpointError, match="no trained ensemble"):
        T.load_ensemble(out / "nowhere")


def test_corrupt_saved_ensemble_is_a_clear_error(full_run, tmp_path):
    import shutil

    out, _, _ = full_run
    bad = tmp_path / "ensemble"
    shutil.copytree(out / "ensemble", bad)
    for f in (bad / "params").rglob("*"):
        if f.is_file() and f.stat().st_size > 0:
            f.write_bytes(b"\x00garbage" * 10)
    with pytest.raises(T.CheckpointError, match="corrupt"):
        T.load_ensemble(bad)
    (bad / "ensemble.json").write_text("{not json")
    with pytest.raises(T.CheckpointError, match="corrupt"):
        T.load_ensemble(bad)


def test_resume_gives_the_uninterrupted_result(env, datasets, full_run, tmp_path):
    _, ens, hist = full_run
    partial, _ = T.train_ensemble(
        datasets, env, MODEL, TRAIN, seed=SEED, ckpt_dir=tmp_path, progress=False, stop_after=16
    )
    assert (tmp_path / "checkpoints" / "16").is_dir() and not (tmp_path / "ensemble").exists()
    with pytest.raises(T.CheckpointError, match="not finished"):
        T.load_ensemble(tmp_path)
    resumed, h2 = T.train_ensemble(
        datasets, env, MODEL, TRAIN, seed=SEED, ckpt_dir=tmp_path, progress=False
    )
    _assert_trees_close(resumed.params, ens.params, rtol=0, atol=0)
    np.testing.assert_array_equal(h2.train_loss, hist.train_loss)
    # a finished run re-run is a no-op that returns the same result
    again, _ = T.train_ensemble(
        datasets, env, MODEL, TRAIN, seed=SEED, ckpt_dir=tmp_path, progress=False
    )
    _assert_trees_close(again.params, ens.params, rtol=0, atol=0)


def test_mismatched_and_corrupt_checkpoints_are_clear_errors(env, datasets, tmp_path):
    T.train_ensemble(
        datasets, env, MODEL, TRAIN, seed=SEED, ckpt_dir=tmp_path, progress=False, stop_after=4
    )
    other = TrainConfig(**{**TRAIN.__dict__, "learning_rate": 0.1})
    with pytest.raises(T.CheckpointError, match="different run(.|\n)*learning_rate"):
        T.train_ensemble(datasets, env, MODEL, other, seed=SEED, ckpt_dir=tmp_path, progress=False)
    with pytest.raises(T.CheckpointError, match="different run(.|\n)*data"):
        T.train_ensemble(
            datasets[:3] + [datasets[0]],
            env,
            MODEL,
            TRAIN,
            seed=SEED,
            ckpt_dir=tmp_path,
            progress=False,
        )
    for f in (tmp_path / "checkpoints" / "4" / "state").rglob("*"):
        if f.is_file() and f.stat().st_size > 0:
            f.write_bytes(b"\x00garbage" * 10)
    with pytest.raises(T.CheckpointError, match="corrupt|unreadable"):
        T.train_ensemble(datasets, env, MODEL, TRAIN, seed=SEED, ckpt_dir=tmp_path, progress=False)


_CHILD_COMMON = """
import json, os, sys, time
import numpy as np
sys.path.insert(0, {tests!r})
from test_train import MODEL, TRAIN, SEED, PATHS, straight_paths
from ntq_jax import make_env
from ntq_jax import training as T
{prelude}
env = make_env("point/0")
datasets = [straight_paths(n, 100 + i) for i, n in enumerate(PATHS)]

def sharded_run(n_devices, out_file):
    # trains with shard=None on this process's devices, checks that every placed array
    # is spread over n_devices, saves the parameters to out_file
    import jax
    assert len(jax.devices()) == n_devices, jax.devices()
    from ntq_jax.training import devices
    seen, place = [], devices.place
    def spy(tree, mesh, axis=0):
        r = place(tree, mesh, axis)
        seen.extend(len(x.sharding.device_set) for x in jax.tree.leaves(r))
        return r
    devices.place = spy
    try:
        ens_s, _ = T.train_ensemble(datasets, env, MODEL, TRAIN, seed=SEED, progress=False)
    finally:
        devices.place = place
    assert set(seen) == {{n_devices}}, set(seen)
    np.savez(out_file, *[np.asarray(x) for x in jax.tree.leaves(ens_s.params)])
"""


def _assert_saved_params_close(out_file, ens):
    """The parameters a child saved (``sharded_run``) == ``ens``'s, to round-off."""
    with np.load(out_file) as z:
        for i, leaf in enumerate(jax.tree.leaves(ens.params)):
            np.testing.assert_allclose(z[f"arr_{i}"], np.asarray(leaf), rtol=1e-5, atol=SHARD_ATOL)


def _run_child(code: str, env_extra: dict | None = None, prelude: str = "", **popen):
    """A Python child running ``prelude`` (before any JAX operation), the common setup,
    then ``code``."""
    env = dict(os.environ, JAX_PLATFORMS="cpu", **(env_extra or {}))
    src = (
        textwrap.dedent(_CHILD_COMMON.format(tests=str(Path(__file__).parent), prelude=prelude))
        + code
    )
    return subprocess.Popen(
        [sys.executable, "-c", src],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **popen,
    )


def test_sharded_run_agrees_and_resumes_after_kill9(env, datasets, full_run, tmp_path):
    """One child process with four CPU devices: (1) a full run with the member axis sharded
    one member per device, which must agree with this process's one-device run; (2) the same
    run with checkpoints, killed with SIGKILL right after its first checkpoint. Re-running
    the same call here (one device) resumes from that checkpoint and finishes with the
    uninterrupted result."""
    _, ens, _ = full_run
    out_file, run_dir = tmp_path / "sharded.npz", tmp_path / "run"
    child = _run_child(
        textwrap.dedent(f"""
        sharded_run(4, {str(out_file)!r})  # shard=None: automatic with >= 4 devices
        def hook(step):
            print("CHECKPOINT", step, flush=True)
            time.sleep(600)  # wait here to be killed
        T.train_ensemble(datasets, env, MODEL, TRAIN, seed=SEED, ckpt_dir={str(run_dir)!r},
                         progress=False, on_checkpoint=hook)
        print("FINISHED", flush=True)
    """),
        {"XLA_FLAGS": "--xla_force_host_platform_device_count=4"},
    )
    try:
        line = child.stdout.readline()
        if not line.startswith("CHECKPOINT"):
            child.wait(timeout=60)
            pytest.fail(f"child: {line!r}\n{child.stderr.read()[-3000:]}")
        os.kill(child.pid, signal.SIGKILL)
        child.wait(timeout=30)
    finally:
        if child.poll() is None:
            child.kill()
    assert child.returncode == -signal.SIGKILL
    _assert_saved_params_close(out_file, ens)  # sharded == unsharded
    assert (run_dir / "checkpoints" / str(TRAIN.checkpoint_every)).is_dir()
    assert not (run_dir / "ensemble").exists()
    resumed, _ = T.train_ensemble(
        datasets, env, MODEL, TRAIN, seed=SEED, ckpt_dir=run_dir, progress=False
    )
    _assert_trees_close(resumed.params, ens.params, rtol=1e-5, atol=SHARD_ATOL)
    assert T.load_ensemble(run_dir).num_members == 4


@pytest.mark.parametrize(
    "members, devices, size",
    [(4, 1, 1), (4, 2, 2), (4, 3, 2), (4, 4, 4), (4, 8, 4), (3, 2, 1), (3, 4, 3), (1, 4, 1)],
)
def test_mesh_size_gives_every_device_an_equal_share(members, devices, size):
    assert T.mesh_size(members, devices) == size


def test_two_cpu_devices_hold_two_members_each(env, datasets, full_run, tmp_path):
    """``use_cpu_devices(2)`` in a fresh process gives two CPU devices; the ensemble
    then shards two members per device and ends where the one-device run ends;
    afterwards the device count can no longer change (a clear RuntimeError)."""
    _, ens, _ = full_run
    out_file = tmp_path / "two.npz"
    child = _run_child(
        textwrap.dedent(f"""
        sharded_run(2, {str(out_file)!r})
        try:
            T.use_cpu_devices(3)
        except RuntimeError as e:
            assert "before any JAX operation" in str(e), e
        else:
            raise AssertionError("use_cpu_devices after a computation did not raise")
        print("OK", flush=True)
    """),
        {"XLA_FLAGS": ""},
        prelude="assert T.use_cpu_devices(2) == 2",
    )
    out, err = child.communicate(timeout=300)
    assert child.returncode == 0 and "OK" in out, err[-3000:]
    _assert_saved_params_close(out_file, ens)


def test_adagrad_first_step_and_its_initial_accumulator():
    """Accumulator 0 (as PyTorch's Adagrad, MPNet's): the first update is lr * sign(grad)
    on every weight, whatever the gradient's size; 0.1 (the paper-width configs):
    lr * g / sqrt(0.1 + g^2). (optax adds eps = 1e-10 under the square root.)"""
    import jax.numpy as jnp

    g = np.array([1e-3, -0.5, 2.0])
    p = {"w": jnp.zeros(3)}
    for acc in (0.0, 0.1):
        tx = T.make_optimizer(TrainConfig(adagrad_initial_accumulator=acc))
        upd, _ = tx.update({"w": jnp.asarray(g, jnp.float32)}, tx.init(p), p)
        np.testing.assert_allclose(
            np.asarray(upd["w"]), -0.01 * g / np.sqrt(acc + g**2 + 1e-10), rtol=1e-5
        )
        if acc == 0.0:
            np.testing.assert_allclose(np.asarray(upd["w"]), -0.01 * np.sign(g), rtol=1e-4)

"""The chunked query stream (ntq_jax.data.stream): determinism, resume, redo, verification."""

import numpy as np
import pytest

from ntq_jax import make_env
from ntq_jax.data import stream as S
from ntq_jax.planners.verify import check_paths
from ntq_jax.queries import NON_TRIVIAL, NT_EXHAUSTED, UNIFORM
from ntq_jax.types import PlanStatus

N, CHUNK = 24, 8
OPTS = {"milestones": 600, "smooth_chunk": 8}


@pytest.fixture(scope="module")
def env():
    return make_env("rigid/0")


@pytest.fixture(scope="module")
def full(env, tmp_path_factory):
    """A complete stream, made in two runs: 2 chunks, then the rest."""
    out = tmp_path_factory.mktemp("stream")
    kw = dict(n_queries=N, chunk=CHUNK, seed=3, options=dict(OPTS))
    first = S.stream_chunks(env, out, max_chunks=2, **kw)
    mtimes = {i: S.chunk_path(out, i).stat().st_mtime_ns for i in first.planned}
    second = S.stream_chunks(env, out, **kw)
    return out, kw, first, second, mtimes


def test_chunk_queries_deterministic_per_seed_and_index(env):
    a, ka = S.chunk_queries(env, 3, 5, 6, env.padding)
    b, kb = S.chunk_queries(env, 3, 5, 6, env.padding)
    c, _ = S.chunk_queries(env, 3, 6, 6, env.padding)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(ka, kb)
    assert not np.array_equal(a, c)
    assert (ka[:3] == UNIFORM).all() and np.isin(ka[3:], [NON_TRIVIAL, NT_EXHAUSTED]).all()


def test_resume_does_not_replan_complete_chunks(full):
    out, _, first, second, mtimes = full
    assert first.planned == [0, 1] and first.skipped == []
    assert second.planned == [2] and second.skipped == [0, 1]
    for i, t in mtimes.items():
        assert S.chunk_path(out, i).stat().st_mtime_ns == t
    third = S.stream_chunks(make_env("rigid/0"), out, **full[1])
    assert third.planned == [] and third.queries == 0


def test_every_path_verifies_and_half_are_non_trivial(env, full):
    out = full[0]
    kinds = []
    for i in range(N // CHUNK):
        z = np.load(S.chunk_path(out, i))
        assert (z["status"] == PlanStatus.SOLVED).all()
        ok, costs = check_paths(env, z["paths"], z["lengths"], env.padding, "certified")
        assert ok.all()
        np.testing.assert_allclose(costs, z["costs"], rtol=1e-6)
        np.testing.assert_array_equal(z["paths"][np.arange(CHUNK), 0], z["queries"][:, 0])
        assert list(z["stages"]) == list(S.STAGES) and (z["timings"] >= 0).all()
        kinds.append(z["kind"])
    kinds = np.concatenate(kinds)
    assert (kinds != UNIFORM).sum() == N // 2


def test_chunk_content_does_not_depend_on_the_run(env, full, tmp_path):
    out, kw = full[0], full[1]
    S.stream_chunks(env, tmp_path, **kw, shard=(1, 3))  # chunk 1 alone, in another folder
    a, b = np.load(S.chunk_path(out, 1)), np.load(S.chunk_path(tmp_path, 1))
    for k in ("queries", "paths", "lengths", "status", "fingerprint"):
        np.testing.assert_array_equal(a[k], b[k])
    assert not S.chunk_path(tmp_path, 0).exists()


def test_corrupt_or_foreign_chunk_is_made_again(env, full, tmp_path):
    out, kw = full[0], full[1]
    for i in range(N // CHUNK):
        S.chunk_path(tmp_path, i).write_bytes(S.chunk_path(out, i).read_bytes())
    S.chunk_path(tmp_path, 0).write_bytes(b"not an npz")
    z = dict(np.load(S.chunk_path(out, 2)))
    z["fingerprint"] = np.array("someone else's")
    np.savez(S.chunk_path(tmp_path, 2), **z)
    rep = S.stream_chunks(env, tmp_path, **kw)
    assert rep.planned == [0, 2] and rep.skipped == [1]
    other = S.stream_chunks(env, tmp_path, **dict(kw, seed=4), max_chunks=1)
    assert other.planned == [0]

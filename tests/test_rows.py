"""plan_rows splits any batch into in-place pieces and one small edge (pure Python, no JAX)."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from ntq_jax.batching import fine_bucket_size
from ntq_jax.robots.rows import RowPlan, plan_rows


def _check_plan(p: RowPlan, n: int, head: int, period: int, piece_max: int, piece_min: int):
    covered = p.head  # rows [0, head) are the edge's
    sizes = {piece_max} | {piece_min << k for k in range(20) if piece_min << k <= piece_max}
    for lo, size in p.pieces:
        assert size in sizes
        assert p.head <= lo <= covered, (p, "a gap or a piece before the head")
        assert (lo - p.head) % period == 0, (p, "a piece off the aligned rows")
        assert lo + size <= n
        covered = lo + size
    assert covered == p.tail and p.tail <= n
    assert p.edge_rows == p.head + n - p.tail
    assert (p.bucket == 0) == (p.edge_rows == 0) and p.bucket >= p.edge_rows
    if p.pieces:
        assert p.n - p.tail < max(piece_min, period) and p.head == head
    work = sum(size for _, size in p.pieces) + p.bucket
    assert work <= 1.25 * n + 64 + period, (p, work)  # at most a quarter more than the rows


@settings(max_examples=400, deadline=None)
@given(n=st.integers(1, 1 << 24), head=st.integers(0, 15), period=st.sampled_from([1, 8, 16]))
def test_flexible_plans_cover_every_row_once_in_order(n, head, period):
    head = head - head % period if period > 1 else head
    p = plan_rows(n, head, 1 << 20, 1 << 13, 64, period)
    _check_plan(p, n, head, period, 1 << 20, 1 << 13)
    if n < head + (1 << 13):
        assert p.pieces == () and p.bucket == fine_bucket_size(n, 64)


@settings(max_examples=200, deadline=None)
@given(n=st.integers(1, 100_000), head=st.integers(0, 15))
def test_fixed_plans_have_one_shape(n, head):
    p = plan_rows(n, head, 1024, 1024, 1024)
    assert all(size == 1024 for _, size in p.pieces)
    assert p.bucket in (0, 1024) or (p.bucket > 1024 and p.head > 0)


def test_examples():
    assert plan_rows(1 << 20, 0) == RowPlan(1 << 20, 0, ((0, 1 << 20),), 1 << 20, 0)
    # an unaligned batch of 2^20 rows: two halves, the second overlapping by a few rows
    p = plan_rows(1 << 20, 6, period=8)
    assert p.pieces == ((6, 1 << 19), ((1 << 19) - 2, 1 << 19)) and p.edge_rows == 8
    assert plan_rows(65, 0) == RowPlan(65, 0, (), 0, 80)
    assert fine_bucket_size(65, 64) == 80 and fine_bucket_size(2049, 64) == 2560

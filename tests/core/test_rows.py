"""The row store (core.rows.RowStore): rows kept compact per batch, assembled into dense blocks.

Oracle: the dense rows themselves. Each batch keeps only the columns its rows hit; assembling
any subset of rows and columns, in any order, must give those entries of the dense matrix.
"""

import numpy as np
import pytest

from core import rows as rows_module
from core.rows import RowStore, compact_rows


def _store(n_rows, n_cols, rng, batch_sizes):
    """A store of sparse random rows in batches of the given sizes, and the dense matrix."""
    dense = rng.random((n_rows, n_cols)) * (rng.random((n_rows, n_cols)) < 0.3)
    dense = dense.astype(np.float32).astype(np.float64)   # what a float32 store can hold
    store = RowStore(n_rows, n_cols)
    keys = rng.permutation(n_rows)
    start = 0
    for size in batch_sizes:
        k = np.sort(keys[start:start + size])
        start += size
        cols, vals = compact_rows(dense[k])
        store.add_compact(k, cols, vals)
    assert start == n_rows
    return store, dense


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_assemble_gives_the_dense_rows_and_columns_asked_for(dtype, monkeypatch):
    # A step of 3 rows splits the batches of 7 and 5 rows into parts (ASSEMBLE_ROWS).
    monkeypatch.setattr(rows_module, "ASSEMBLE_ROWS", 3)
    rng = np.random.default_rng(0)
    store, dense = _store(20, 30, rng, [1, 7, 5, 7])
    for rows, cols in ((np.arange(20), np.arange(30)),
                       (rng.permutation(20)[:11], rng.permutation(30)[:17]),
                       (np.array([4]), np.array([29, 0, 3]))):
        got = store.assemble(rows, cols, dtype)
        assert got.dtype == dtype
        np.testing.assert_array_equal(got, dense[np.ix_(rows, cols)].astype(dtype))


def test_a_half_store_keeps_every_value_to_12_bits_and_each_chunk_only_its_columns(monkeypatch):
    # Oracle: each value's significand rounded to 12 bits (frexp, ties to even), 0 kept 0, so
    # within 2^-12 of itself; then each row scaled back to its own sum. Values from 1e-8 (above
    # 2^-28, where the format is normal) to 1.
    monkeypatch.setattr(rows_module, "HALF_CHUNK", 4)
    rng = np.random.default_rng(3)
    n_rows, n_cols = 23, 60
    dense = np.zeros((n_rows, n_cols))
    for r in range(n_rows):                 # each row hits its own few columns
        cols = rng.choice(n_cols, 6, replace=False)
        dense[r, cols] = 10.0 ** rng.uniform(-8, 0, 6)
    dense = dense.astype(np.float32).astype(np.float64)
    full, half = RowStore(n_rows, n_cols), RowStore(n_rows, n_cols, half=True)
    keys = rng.permutation(n_rows)
    for part in (keys[:9], keys[9:10], keys[10:]):
        k = np.sort(part)
        for store in (full, half):
            store.add_compact(k, *compact_rows(dense[k]))
    m, e = np.frexp(dense)
    rounded = np.ldexp(np.round(m * 2.0 ** 12) / 2.0 ** 12, e)
    assert np.all(np.abs(rounded - dense) <= 2.0 ** -12 * dense)
    assert not np.array_equal(rounded, dense)      # the rounding is there to be seen
    rounded *= (dense.sum(axis=1) / rounded.sum(axis=1))[:, None]
    every = np.arange(n_rows)
    np.testing.assert_allclose(half.rows(every), rounded, rtol=1e-14)
    np.testing.assert_allclose(half.assemble(every, np.arange(n_cols), np.float64), rounded,
                               rtol=1e-14)
    r, c = np.nonzero(dense)
    np.testing.assert_allclose(half.entries(r, c), rounded[r, c], rtol=1e-7)
    np.testing.assert_allclose(half.rows(every).sum(axis=1), dense.sum(axis=1), rtol=1e-14)
    assert np.all(np.abs(half.rows(every) - dense) <= 2.0 ** -11 * dense)
    L = rng.random((n_cols, 3))
    np.testing.assert_allclose(half.incident(L), rounded @ L, rtol=1e-12)
    np.testing.assert_array_equal(half.row_sums, full.row_sums)   # of the values as given
    assert half.copy().half and np.array_equal(half.copy().scale, half.scale)
    # 8 batches of at most 4 rows (9 -> 4 + 4 + 1, 1, 13 -> 4 + 4 + 4 + 1), each only the
    # columns its rows hit: fewer values than the float32 store's 3 batches, at 2 bytes each.
    assert len(half.batches) == 8
    n_half = sum(v.size for _, _, v in half.batches)
    n_full = sum(v.size for _, _, v in full.batches)
    assert n_half < n_full
    assert all(v.dtype == np.uint16 for _, _, v in half.batches)
    assert half.nbytes < full.nbytes


def test_a_half_store_rounds_ties_to_even_keeps_tiny_values_and_refuses_out_of_range():
    # 1 + 2^-12 lies halfway between 1 and 1 + 2^-11: ties go to the even significand (1);
    # 1 + 3 x 2^-12 goes up to 1 + 2^-10. Below 2^-28 the format keeps 2^-40 absolute.
    vals = np.array([[0.0, 1.0 + 2.0 ** -12, 1.0 + 3 * 2.0 ** -12, 3.0e-10, 3.99]],
                    dtype=np.float32)
    got = rows_module.decode_half(rows_module.encode_half(vals))
    assert got[0, 0] == 0.0 and got[0, 1] == 1.0 and got[0, 2] == 1.0 + 2.0 ** -10
    assert abs(got[0, 3] - 3.0e-10) <= 2.0 ** -40
    assert abs(got[0, 4] - 3.99) <= 2.0 ** -12 * 3.99
    for bad in (4.0, -1e-3, np.nan):
        with pytest.raises(ValueError, match=r"\[0, 4\)"):
            rows_module.encode_half(np.array([[0.5, bad]]))

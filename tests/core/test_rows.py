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

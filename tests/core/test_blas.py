"""core.blas: one OpenBLAS thread inside ``one_thread()``, the counts before restored after it.

The oracle is OpenBLAS's own count (``openblas_get_num_threads``), read through the same
library the products use. A wheel of NumPy that ships OpenBLAS (``numpy.libs``) must be found:
otherwise a bake's process would again spin BLAS threads on the workers' cores.
"""

import glob
import os

import numpy as np
import pytest

from core import blas

BUNDLED = glob.glob(os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs",
                                 "*openblas*"))


def test_a_wheel_s_openblas_is_found():
    if not BUNDLED:
        pytest.skip("this NumPy does not bundle OpenBLAS (a system BLAS: nothing to hold)")
    assert blas.threads(), f"OpenBLAS in {BUNDLED} was not found"


def test_one_thread_inside_and_the_counts_back_after_even_on_an_error():
    before = blas.threads()
    with pytest.raises(RuntimeError):
        with blas.one_thread():
            assert blas.threads() == [1] * len(before)
            with blas.one_thread():                  # nested: the inner exit keeps one
                pass
            assert blas.threads() == [1] * len(before)
            a = np.random.default_rng(0).normal(size=(300, 300))
            assert np.allclose(a @ np.eye(300), a)   # products still work with one thread
            raise RuntimeError("inside")
    assert blas.threads() == before

"""The CPU operations of hybmss._cpu: atomics, the flush-to-zero mode."""

from __future__ import annotations

import numpy as np
from numba import njit

from hybmss._cpu import (FTZ_DAZ, atomic_add, atomic_load, atomic_store, flush_subnormals, get_fp_mode,
                         restore_fp_mode)


@njit
def _product(a, b, flush):
    old = flush_subnormals() if flush else get_fp_mode()
    p = a[0] * b[0]
    inside = get_fp_mode()
    restore_fp_mode(old)
    return p, inside, get_fp_mode() == old


def test_flush_subnormals_zeroes_results_below_the_normal_range_and_restores_the_mode():
    a, b = np.array([1e-30], np.float32), np.array([1e-10], np.float32)
    p, inside, restored = _product(a, b, False)
    assert 0.0 < p < np.finfo(np.float32).tiny  # a subnormal float32 (1e-40)
    p, inside, restored = _product(a, b, True)
    assert p == 0.0 and inside & FTZ_DAZ == FTZ_DAZ and restored
    # normal numbers are untouched
    p, _, _ = _product(np.array([1e-20], np.float32), np.array([1e-10], np.float32), True)
    assert p == np.float32(1e-20) * np.float32(1e-10)


@njit
def _atomics(S):
    old = atomic_add(S, 1, 5)
    atomic_store(S, 2, 7)
    return old, atomic_load(S, 1), atomic_load(S, 2)


def test_atomics_return_the_old_value_and_store():
    S = np.array([0, 3, 0], dtype=np.int64)
    assert _atomics(S) == (3, 8, 7)
    assert S.tolist() == [0, 8, 7]

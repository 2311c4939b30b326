"""The performance study's timing protocol: a short run is lengthened (a multiple of its steps)
until its repeats span the minimum, never beyond the span of the most repeats; a kernel is
taken as cached only when its module and Numba's index of it are in the cache."""

import math

import pytest

from studies.paper import performance as perf


@pytest.mark.parametrize("steps,t_est,repeats,span", [(1000, 0.024, 3, 0.5), (1000, 0.3, 3, 0.5),
                                                       (200, 0.001, 2, 0.5), (300, 0.17, 3, 0.5),
                                                       (1000, 1e-5, 3, 0.5), (20, 0.01, 1, 0.0)])
def test_run_steps_spans_the_minimum_with_the_fewest_steps(steps, t_est, repeats, span):
    n = perf.run_steps(steps, t_est, repeats, span)
    assert n % steps == 0 and n >= steps
    k = n // steps
    cap = math.ceil(perf.MAX_REPEATS / repeats)
    if repeats * t_est >= span:
        assert n == steps  # long enough: the protocol's steps, the first round counts
    elif k < cap:
        assert repeats * t_est * k >= span  # the repeats span the minimum
        assert repeats * t_est * (k - 1) < span  # and one multiple fewer would not
    else:
        assert k == cap and repeats * t_est * k < span  # capped at the span of MAX_REPEATS runs


def test_kernel_cached_needs_the_module_and_numbas_index(tmp_path, monkeypatch):
    monkeypatch.setenv("HYBMSS_KERNEL_CACHE", str(tmp_path))
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    key = "0123456789abcdef0123"
    assert not perf.kernel_cached(key)
    (tmp_path / f"hybmss_stencil_{key}.py").write_text("# kernel\n")
    assert not perf.kernel_cached(key)  # no machine code cached yet
    (tmp_path / "__pycache__").mkdir()
    (tmp_path / "__pycache__" / f"hybmss_stencil_{key}x.run-8.py311.nbi").write_bytes(b"")
    assert not perf.kernel_cached(key)  # another kernel's index
    (tmp_path / "__pycache__" / f"hybmss_stencil_{key}.run-8.py311.nbi").write_bytes(b"")
    assert perf.kernel_cached(key)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "elsewhere"))
    assert not perf.kernel_cached(key)  # the index is then elsewhere: compile as before

"""The [G20] per-step claim counts the meshes whose step fits in the last-level cache; the others,
bound by DRAM traffic the machine shares, are shown apart."""

from __future__ import annotations

import numpy as np
import pandas as pd

from studies.paper.claims import NOT, REPRODUCED, _perf_summary_claim, memory_bound_meshes
from studies.paper.performance import last_level_cache_bytes

MESHES = ["10x10x10", "30x30x30"]


def tables(ratio_cf_big: float, llc_MB: float | None):
    """A summary with hybmss-cf at 1.3 on the 10³ cube and ``ratio_cf_big`` on 30³ (publication 1.4),
    the performance table's bytes a step (5 and 40 MiB), and the bandwidth table's cache size."""
    summ = pd.DataFrame({
        "scene": "compression", "mesh": np.repeat(MESHES, 2), "threads": 1, "variant": ["hybmss-fd", "hybmss-cf"] * 2,
        "nu": 0.3, "baseline": "hybmss-fd", "ratio_to_baseline": [1.0, 1.3, 1.0, ratio_cf_big],
        "paper_ratio_to_baseline": [np.nan, 1.4, np.nan, 1.4]})
    perf = summ[["mesh", "threads", "variant"]].assign(bytes_per_step=np.repeat([5, 40], 2) * 2**20)
    bw = None if llc_MB is None else pd.DataFrame([{"ceiling": 10.0, "llc_MB": llc_MB}])
    return summ, perf, bw


def test_a_memory_bound_mesh_is_shown_apart_and_not_counted():
    summ, perf, bw = tables(2.8, 32.0)
    bound = memory_bound_meshes(perf, bw)
    assert bound == ({"30x30x30": 40.0}, 32.0)
    c = _perf_summary_claim(summ, bound)
    assert c.verdict == REPRODUCED and c.counted == 1 and c.within == 1
    assert "not counted, bound by DRAM traffic the machine shares: 30x30x30 (40 MiB a step): hybmss-cf 2.8–2.8" in c.evidence
    assert "32 MiB last-level cache not counted" in c.criterion


def test_every_mesh_counts_without_a_stored_cache_size_or_when_it_fits():
    for llc in (None, 64.0):
        summ, perf, bw = tables(2.8, llc)
        c = _perf_summary_claim(summ, memory_bound_meshes(perf, bw))
        assert c.verdict == NOT and c.counted == 2 and c.within == 1 and "not counted" not in c.evidence
    summ, perf, bw = tables(1.5, 32.0)  # a cache-resident mesh outside the tolerance still fails the claim
    summ.loc[1, "ratio_to_baseline"] = 2.2
    assert _perf_summary_claim(summ, memory_bound_meshes(perf, bw)).verdict == NOT


def test_last_level_cache_is_the_highest_level_sysfs_lists(tmp_path):
    for index, level, size in (("index0", 1, "32K"), ("index2", 2, "1024K"), ("index3", 3, "32768K")):
        (tmp_path / index).mkdir()
        (tmp_path / index / "level").write_text(f"{level}\n")
        (tmp_path / index / "size").write_text(f"{size}\n")
    assert last_level_cache_bytes(str(tmp_path)) == 32 * 2**20
    assert last_level_cache_bytes(str(tmp_path / "none")) is None

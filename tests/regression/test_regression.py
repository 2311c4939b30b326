"""CI regression: the quick subset's errors against the FEM must not exceed the committed
baseline (studies/data/regression_baseline.csv) beyond its per-metric tolerances."""

import pandas as pd
import pytest

from studies.paper.regression import load_baseline, load_tolerances, measure, regressions, unbaselined


@pytest.mark.slow
def test_errors_do_not_regress():
    now = measure(jobs=1)
    problems = regressions(now, load_baseline(), load_tolerances())
    assert not problems, "\n".join(problems)


def test_regression_check_catches_a_worse_metric():
    base = load_baseline()
    worse = base.copy()
    worse.loc[0, "rel_l2"] = base.loc[0, "rel_l2"] * 1.5 + 1e-3
    assert regressions(worse, base, load_tolerances())
    assert not regressions(base, base, load_tolerances())
    missing = base.iloc[1:]
    assert any("only in the baseline" in p for p in regressions(pd.DataFrame(missing), base, load_tolerances()))
    # a model with no baseline yet (a new or another package's model) is measured, not compared
    new = base[base["model"] == base["model"].iloc[0]].assign(model="another-model", rel_l2=99.0)
    assert unbaselined(pd.concat([base, new]), base) == ["another-model"]
    assert not regressions(pd.concat([base, new]), base, load_tolerances())
    # ... while a case of a baselined model that appears only now still counts
    extra = base.iloc[:1].assign(case="compression 9x9x9 nu=0")
    assert any("only in the current run" in p for p in regressions(pd.concat([base, extra]), base, load_tolerances()))

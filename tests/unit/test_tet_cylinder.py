"""The cylinder squeeze/twist runner refuses sizes and levels outside their ranges (exit 2, one line)."""

import pytest

from studies.paper.tet_cylinder import main


@pytest.mark.parametrize("argv,key", [(["--h", "0"], "--h"), (["--h", "nan"], "--h"), (["--levels", "5"], "--levels"),
                                      (["--levels", "1"], "--levels")])
def test_refused_before_work(argv, key, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(key) and "not allowed" in err[0]

"""The conv-backward benchmark (profile/conv_backward.py) times every form on every shape asked
for and prints the table the Winograd thresholds are read from."""

import pytest

from dsfec_jax.profile import conv_backward


def test_the_table_has_a_row_per_shape_and_every_form_timed(capsys):
    assert conv_backward.main(["--sizes", "4,8", "--channels", "2", "--batch", "1", "--repeats", "1"]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("| ") and line[2].isdigit()]
    assert [r.split(" | ")[:2] for r in rows] == [["| 4", "2"], ["| 8", "2"]]
    times = [float(v) for r in rows for cell in r.split(" | ")[2:] for v in cell.rstrip("x |").split(" / ")]
    assert len(times) == 2 * 7 and min(times) > 0
    assert "Command: `python -m dsfec_jax.profile.conv_backward --sizes 4,8" in out


@pytest.mark.parametrize("bad", ["0,8", "a", ""])
def test_a_bad_list_names_the_value(bad, capsys):
    with pytest.raises(SystemExit):
        conv_backward.main(["--sizes", bad])
    assert "expected comma-separated integers >= 1" in capsys.readouterr().err

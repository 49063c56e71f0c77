"""tools/real_ax12a.py's reading of the recordings' README table: what it lists is what the tools and tests run.

No recording is needed: each test writes its own README.
"""

import pytest
from emu_testkit import load_tool

tool = load_tool("real_ax12a")

TABLE = """# Some recordings

Text before the table, | with a bar | in it.

| file | servo | load | m (kg) | b (m) | h (m) | J (kg·m²) | overshoot (raw) | undershoot after the peak |
|---|---|---|---|---|---|---|---|---|
| AX12A_NOLOAD_1.csv | AX-12A | none | – | – | – | 0 | 19 | 3 |
| AX12A_LOAD9_2.csv | AX-12A | bar 9 | 0.2 | 0.4 | 0.02 | 2.673e-3 | 30 | 4 |

| other | table |
|---|---|
| x.csv | y |
"""


def test_every_row_of_the_table_is_a_recording_with_its_load(tmp_path):
    (tmp_path / "README.md").write_text(TABLE, encoding="utf-8")
    recs = tool.read_recordings(tmp_path)
    assert [(r.file, r.servo, r.load_kg_m2, r.readme_overshoot, r.readme_dip) for r in recs] == [
        ("AX12A_NOLOAD_1.csv", "AX-12A", 0.0, 19, 3), ("AX12A_LOAD9_2.csv", "AX-12A", 2.673e-3, 30, 4)]


def test_a_row_that_cannot_be_read_is_named(tmp_path):
    (tmp_path / "README.md").write_text(TABLE.replace("2.673e-3", "heavy"), encoding="utf-8")
    with pytest.raises(ValueError, match=r"README.md:8: .*AX12A_LOAD9_2.csv"):
        tool.read_recordings(tmp_path)


def test_no_readme_lists_nothing_and_the_tool_says_what_is_missing(tmp_path, capsys):
    assert tool.read_recordings(tmp_path) == ()
    assert tool.main(["--data", str(tmp_path)]) == 2
    assert "not found" in capsys.readouterr().err


def test_dashed_or_missing_figures_are_none_and_a_dashed_j_with_no_load_is_no_load(tmp_path):
    """A folder of more recordings may leave a figure out: the row is still a recording."""
    table = ("| file | servo | load | J (kg·m²) | overshoot (raw) |\n|---|---|---|---|---|\n"
             "| AX12A_NOLOAD_2.csv | AX-12A | none | – | 19–21 |\n"
             "| AX12A_LOAD1_1.csv | AX-12A | bar 1 | 4.57e-3 | ? |\n")
    (tmp_path / "README.md").write_text(table, encoding="utf-8")
    recs = tool.read_recordings(tmp_path)
    assert [(r.file, r.load_kg_m2, r.readme_overshoot, r.readme_dip) for r in recs] == [
        ("AX12A_NOLOAD_2.csv", 0.0, None, None), ("AX12A_LOAD1_1.csv", 4.57e-3, None, None)]


@pytest.mark.parametrize("j", ["–", "-2.673e-3", "inf", "nan"])
def test_a_j_that_is_not_an_inertia_is_named_not_taken_for_no_load(tmp_path, j):
    (tmp_path / "README.md").write_text(TABLE.replace("2.673e-3", j), encoding="utf-8")
    with pytest.raises(ValueError, match=r"README.md:8: .*AX12A_LOAD9_2.csv"):
        tool.read_recordings(tmp_path)


def test_the_twin_is_fitted_only_on_an_unloaded_ax12a_step(tmp_path, capsys):
    (tmp_path / "README.md").write_text(TABLE, encoding="utf-8")
    assert tool.main(["--data", str(tmp_path), "--fit-on", "AX12A_LOAD9_2.csv"]) == 2
    assert "AX12A_LOAD9_2.csv" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:
        tool.main(["--data", str(tmp_path), "--fit-on", "../AX12A_NOLOAD_1.csv"])
    assert exit_info.value.code == 2
    assert "not a path" in capsys.readouterr().err

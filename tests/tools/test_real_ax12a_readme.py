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

"""tools/real_ax12a.py on data it cannot use: one line naming the file on stderr, exit status 2, no traceback.

The exports here are written by the test (the Wizard 2 graph format the real ones use), so these run without
the recordings in ../shared/reference.
"""

from pathlib import Path

import numpy as np
import pytest
from emu_testkit import load_tool

tool = load_tool("real_ax12a")

_HEADER = ["DYNAMIXEL Graph,2", "AX-12A,12", "ItemCount,1", "Present Position,#ffff00,0,1,0",
           "Time[ms],Present Position"]


def _step_rows(end_ms: int) -> list[str]:
    """A step 1 -> 500 starting at 800 ms, one row per 16 ms tick up to ``end_ms``."""
    t_ms = np.arange(0, end_ms, 16)
    pos = np.where(t_ms < 800, 1, 500 - 499 * np.exp(-np.clip(t_ms - 800, 0, None) / 120.0))
    return [f"{t},{int(round(p))}" for t, p in zip(t_ms, pos)]


def _write(folder: Path, text: str) -> Path:
    folder.mkdir()
    (folder / tool.FIT_ON).write_text(text, encoding="utf-8")
    return folder


CASES = {
    "empty file": ("", "empty file"),
    "header only": ("\n".join(_HEADER) + "\n", "need at least two readable data rows"),
    "non-numeric rows": ("\n".join(_HEADER + ["0,abc", "16,x", "32,?"]) + "\n", "need at least two readable"),
    "never moves": ("\n".join(_HEADER + [f"{t},1" for t in range(0, 3000, 16)]) + "\n", "never moves"),
    # cut mid-row 300 ms after the first movement: no settled value to measure overshoot and dip from
    "cut short mid-row": ("\n".join(_HEADER + _step_rows(1100)) + "\n1104,4", "cut short"),
}


@pytest.mark.parametrize("case", CASES)
def test_unusable_export_exits_2_naming_the_file(tmp_path, capsys, case):
    text, words = CASES[case]
    status = tool.main(["--data", str(_write(tmp_path / "data", text))])
    err = capsys.readouterr().err
    assert status == 2, err
    assert len(err.strip().splitlines()) == 1 and tool.FIT_ON in err and words in err, err


def test_a_directory_in_place_of_an_export_exits_2(tmp_path, capsys):
    (tmp_path / "data" / tool.FIT_ON).mkdir(parents=True)
    assert tool.main(["--data", str(tmp_path / "data")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Is a directory" in err, err


def test_a_whole_step_loads(tmp_path):
    """The checks refuse only what is cut short: a step recorded past its settling loads."""
    path = _write(tmp_path / "data", "\n".join(_HEADER + _step_rows(2500)) + "\n")
    rec = tool.load(path / tool.FIT_ON)
    assert rec.first_move_ms == 816 and rec.pos[-1] == 500

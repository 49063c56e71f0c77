"""Every tool on a bad flag or value: exit status 2, one line on stderr saying what is wrong, no traceback.

Why: the tools are run by hand with typed numbers, and a count of 0, a NaN duration or a misspelt effect must
stop at once as argparse's one-line error (``ax12emu.cli.arg_types.OneLineParser``), not as a traceback
minutes into a benchmark, a hang or a 17-line usage block.  A value that only fails once used (a log that
is not there, a port that cannot be opened) is one line too.  Each case runs the tool as a user does, a
subprocess from the repository root; argparse's errors come before any work, so each takes well under a
second (the tools' imports).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

#: tool -> bad command lines (a representative set per tool: each kind of validator it uses).
BAD = {
    "bam_to_trace": [
        ["/nonexistent-ax12emu/log.json", "out.csv"],  # only fails once read
        ["log.json", "/nonexistent-ax12emu/out.csv"],
    ],
    "bench_diagnose": [
        ["--seeds", "-1"],
        ["--effects", "gremlins"],
    ],
    "bench_physics": [
        ["--counts", "0"],
        ["--counts", "x"],
        ["--repeat", "0"],
        ["--seconds", "inf"],
        ["--step-s", "0.5"],  # positive, but too long a step for the model's winding
    ],
    "bench_protocol": [
        ["--seconds", "0"],
        ["--model", "ax-12a"],
    ],
    "bench_protocol2": [
        ["--servos", "0"],
        ["--servos", "253"],
    ],
    "bench_twin": [
        ["--seeds", "0"],
    ],
    "bench_xfirmware": [
        ["--seconds", "0"],
        ["--repeat", "0"],
    ],
    "churn": [
        ["--pty-opens", "-1"],
        ["--intruders", "x"],
    ],
    "crash_state": [
        ["--iterations", "0"],
        ["--state-dir", ""],
        ["--iterations", "1", "--state-dir", "pyproject.toml"],  # a file: the emulator refuses it at its start
    ],
    "fuzz": [
        ["--inputs", "0"],
    ],
    "fuzz2": [
        ["--inputs", "-5"],
        ["--seconds", "0"],
    ],
    "live_dataset": [
        ["--seed", "-1"],
        ["/nonexistent-ax12emu/out.csv", "--key", "key.json"],
        ["out.csv", "--key", "out.csv"],  # the key overwrote the recording
        ["out.csv", "--key", "./out.csv"],  # the same file, spelt otherwise
    ],
    "live_flood": [
        ["--connections", "-1"],
        ["--seconds", "0"],
    ],
    "make_dataset": [
        ["out.csv", "--key", "key.json", "--breakaway", "30"],
        ["out.csv", "--key", "key.json", "--effects", "gremlins"],
        ["out.csv", "--key", "out.csv"],  # the key overwrote the trace
    ],
    "plot_step": [
        ["--volts", "0"],
        ["--volts", "100"],  # positive, but outside the parameters' supply range
        ["--moving-speed", "2000"],
        ["--params", "/nonexistent-ax12emu/params.toml"],  # only fails once read
        ["--degrees", "200"],  # a goal of raw 1194: a real AX-12A refuses it (Range Error)
        ["--duration", "1e9"],  # ran until killed
        ["--out", "x.txt"],  # a traceback after the simulation had run
    ],
    "real_ax12a": [
        ["--goal", "2000"],
    ],
    "real_ax12a_inertia": [
        ["--goal", "-1"],
    ],
    "record": [
        ["/dev/null", "out.csv", "--id", "300"],
        ["/dev/null", "out.csv", "--breakaway", "30"],
    ],
    "screenshots": [
        ["--seconds", "0"],
    ],
    "soak": [
        ["--seconds", "0"],
        ["--seconds", "-1"],
        ["--seconds", "nan"],
        ["--servos", "0"],
        ["--protocol", "2.0", "--servos", "253"],
        ["--attach", "/dev/null", "x"],
        ["--seconds", "1", "--attach", "/dev/nonexistent-ax12emu-port", "1"],  # only fails once opened
    ],
    "twin_check": [
        ["--arm", "nan,0.1"],
        ["--effects", "gremlins"],
    ],
    "xl330_fit": [
        ["--max-evaluations", "0"],
    ],
}

CASES = [(tool, args) for tool, lines in BAD.items() for args in lines]


def test_every_tool_with_a_parser_is_listed():
    """A new tool's flags get their cases here (the scripts that build a parser; fuzz_coverage.py is a module)."""
    parsing = {path.stem for path in (ROOT / "tools").glob("*.py") if "add_argument(" in path.read_text()}
    assert parsing == set(BAD), parsing ^ set(BAD)


@pytest.mark.parametrize(("tool", "args"), CASES, ids=[f"{tool} {' '.join(args) or '-'}" for tool, args in CASES])
def test_a_bad_flag_is_one_line_and_exit_status_2(tool, args):
    result = subprocess.run([sys.executable, f"tools/{tool}.py", *args], capture_output=True, text=True, timeout=60,
                            cwd=ROOT)
    err = result.stderr.strip().splitlines()
    assert result.returncode == 2, (result.returncode, result.stderr, result.stdout[-500:])
    assert "Traceback" not in result.stderr, result.stderr
    assert len(err) == 1 and "error:" in err[0], result.stderr


@pytest.mark.parametrize("tool", ["live_dataset", "make_dataset"])
def test_a_key_on_the_trace_file_is_refused_before_any_work(tool, tmp_path):
    """--key the same file as OUT wrote the key over the recording, silently; now one line, and nothing written."""
    out = tmp_path / "out.csv"
    result = subprocess.run([sys.executable, f"tools/{tool}.py", str(out), "--key", str(tmp_path / "." / "out.csv")],
                            capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert result.returncode == 2 and "--key must not be the trace file" in result.stderr, result.stderr
    assert not out.exists()

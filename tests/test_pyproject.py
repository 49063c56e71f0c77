"""pyproject.toml: the test run's import path, whichever way pytest is started."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: A test module importing firmware_model.xseries (shadowed by tests/firmware_model when the root is not on sys.path).
XSERIES_TESTS = ROOT / "tests" / "firmware_model" / "xseries" / "test_profile.py"


def test_bare_pytest_imports_the_packages_not_the_test_folders_of_the_same_name(tmp_path):
    """The ``pytest`` script (sys.path[0] is its bin folder, not the working folder) from outside the tree."""
    script = Path(sys.executable).parent / "pytest"
    if not script.exists():
        pytest.skip(f"no pytest script beside {sys.executable}")
    run = subprocess.run([str(script), str(XSERIES_TESTS), "-q", "-p", "no:cacheprovider", "-p", "no:randomly"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert "passed" in run.stdout

"""tools/examples: the sample robot code's own pytest suite passes through the plugin."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[2] / "tools" / "examples"


def test_example_suite_passes():
    """pytest on tools/examples (its own rootdir, the plugin from the entry point) passes."""
    result = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(EXAMPLES)],
        cwd=EXAMPLES, capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-2000:]
    assert "5 passed" in result.stdout

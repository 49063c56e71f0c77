"""Fixtures shared by the tests of tools/."""

import pytest
from emu_testkit import load_tool


@pytest.fixture(scope="session")
def real_ax12a_twin():
    """tools/real_ax12a.py's twin fitted on the unloaded real step: (params, volts, scale, replay features).

    One fit per test process (seconds of CPU): test_real_ax12a.py and test_real_ax12a_inertia.py both start
    from it, and the parallel pass runs the two files in one worker (tests/conftest.py, SCHEDULED_TOGETHER).
    Their modules skip where the recordings are absent, before asking for it.
    """
    tool = load_tool("real_ax12a")
    return tool.fit_twin(tool.ServoParams(), tool.load(tool.DEFAULT_DATA / tool.FIT_ON), 500)

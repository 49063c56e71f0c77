"""firmware_model.diagnose.metrics: the sample count the BIC and the intervals use."""

import numpy as np
import pytest

from firmware_model.diagnose.metrics import effective_count


def test_rows_count_by_their_weight():
    """A white residual's rows count one each, or what they weigh: 20 rows of weight one and 80 of a tenth are 28
    readings, not 100."""
    z = np.where(np.arange(100) % 2 == 0, 1.0, -1.0)[:, None]  # no positive lag-1 correlation
    assert effective_count(z) == 100.0
    assert effective_count(z, np.r_[np.ones(20), np.full(80, 0.1)]) == pytest.approx(28.0)


def test_correlated_rows_count_less():
    z = np.repeat(np.where(np.arange(25) % 2 == 0, 1.0, -1.0), 4)[:, None]  # runs of four
    assert effective_count(z) < 50.0

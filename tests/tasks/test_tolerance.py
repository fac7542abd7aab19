import numpy as np
import pytest
from dm_control.utils import rewards

from jarena.tasks.tolerance import SIGMOIDS, tolerance

X = np.linspace(-4, 4, 161).astype(np.float32)


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
@pytest.mark.parametrize("bounds,margin,value_at_margin", [((0, 0), 1.0, 0.1), ((-0.5, 1.0), 2.0, 0.3),
                                                           ((0.2, 0.2), 0.5, 0.0), ((-1, 1), 0.0, 0.1)])
def test_matches_dm_control(sigmoid, bounds, margin, value_at_margin):
    if value_at_margin == 0 and sigmoid not in ("cosine", "linear", "quadratic"):
        with pytest.raises(ValueError, match="value_at_margin"):
            tolerance(X, bounds, margin, sigmoid, value_at_margin)
        return
    expected = rewards.tolerance(X.astype(np.float64), bounds, margin, sigmoid, value_at_margin)
    np.testing.assert_allclose(tolerance(X, bounds, margin, sigmoid, value_at_margin), expected, atol=2e-6)


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="unknown sigmoid 'gauss'.*gaussian"):
        tolerance(X, (0, 0), 1.0, "gauss")
    with pytest.raises(ValueError, match="lower bound"):
        tolerance(X, (1, 0))
    with pytest.raises(ValueError, match="margin must be non-negative"):
        tolerance(X, (0, 0), -1.0)

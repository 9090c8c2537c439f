"""The readable per-step oracle (tests/helpers/oracle.py) and the batched integrators compute the same
steps, to round-off, for every variant with every force type at once."""
import numpy as np
import pytest

from reference_sim.integrators import VARIANTS, get_step
from tests.helpers.oracle import step_readable
from tests.helpers.tolerances import READABLE_VS_BATCHED

from .test_integrators import coupled_problem


@pytest.mark.parametrize("variant", list(VARIANTS))
@pytest.mark.parametrize("decay", [(1.0, 1.0), (0.99, 0.995)])
def test_batched_equals_readable(variant, decay):
    problem = coupled_problem(decay)
    rng = np.random.default_rng(7)
    y = np.tile(problem.initial_packed(), (4, 1))
    y[:, 0:3] += rng.normal(scale=0.1, size=(4, 3))
    y[:, 10:13] += rng.normal(scale=0.5, size=(4, 3))
    y_read = y.copy()
    step = get_step(variant)
    for _ in range(200):
        y = step(problem, y, 2e-3)
        y_read = np.array([step_readable(variant, problem, row, 2e-3) for row in y_read])
    np.testing.assert_allclose(y, y_read, rtol=READABLE_VS_BATCHED, atol=READABLE_VS_BATCHED)

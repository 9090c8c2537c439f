"""The plain-float single-body path equals the batched NumPy definition to round-off, for every variant."""
import numpy as np
import pytest

from cross_checks.tolerances import READABLE_VS_BATCHED
from reference_sim.integrators import VARIANTS, get_step
from reference_sim.scalar import ScalarStepper
from reference_sim.simulate import simulate

from .test_integrators import coupled_problem


@pytest.mark.parametrize("variant", list(VARIANTS))
@pytest.mark.parametrize("decay", [(1.0, 1.0), (0.99, 0.995)])
def test_scalar_equals_batched(variant, decay):
    problem = coupled_problem(decay)
    y_b = problem.initial_packed()[None, :]
    y_s = problem.initial_packed().tolist()
    step_b, step_s = get_step(variant), ScalarStepper(problem, variant, 2e-3).step
    for _ in range(300):
        y_b = step_b(problem, y_b, 2e-3)
        y_s = step_s(y_s)
    np.testing.assert_allclose(np.array(y_s), y_b[0], rtol=READABLE_VS_BATCHED, atol=READABLE_VS_BATCHED)


def test_single_body_simulate_uses_the_scalar_path_and_agrees_with_a_batch_of_one():
    problem = coupled_problem()
    single = simulate(problem, "rk4", 1e-3, 500)
    batch = simulate(problem, "rk4", 1e-3, 500, y0=problem.initial_packed()[None, :])
    assert single.y.shape == (501, 13) and batch.y.shape == (501, 1, 13)
    np.testing.assert_allclose(single.y, batch.y[:, 0], rtol=READABLE_VS_BATCHED, atol=READABLE_VS_BATCHED)

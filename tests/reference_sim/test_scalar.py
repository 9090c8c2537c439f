"""The plain-float single-body path equals the batched NumPy definition to round-off, for every variant."""
import numpy as np
import pytest

from reference_sim.integrators import VARIANTS, get_step
from reference_sim.scalar import ScalarStepper
from reference_sim.simulate import simulate
from tests.helpers.tolerances import READABLE_VS_BATCHED

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


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_scalar_equals_batched_at_a_step_other_than_the_decays_own(variant):
    # decay given per 2e-3 s step, run at 1.5e-3 s: e^{−kΔt} (course types) and −k v in the right-hand side
    problem = coupled_problem((0.99, 0.995))
    y_b = problem.initial_packed()[None, :]
    y_s = problem.initial_packed().tolist()
    step_b, step_s = get_step(variant), ScalarStepper(problem, variant, 1.5e-3).step
    for _ in range(200):
        y_b = step_b(problem, y_b, 1.5e-3)
        y_s = step_s(y_s)
    np.testing.assert_allclose(np.array(y_s), y_b[0], rtol=READABLE_VS_BATCHED, atol=READABLE_VS_BATCHED)


def test_single_body_simulate_uses_the_scalar_path_and_agrees_with_a_batch_of_one():
    problem = coupled_problem()
    single = simulate(problem, "rk4", 1e-3, 500)
    batch = simulate(problem, "rk4", 1e-3, 500, y0=problem.initial_packed()[None, :])
    assert single.y.shape == (501, 13) and batch.y.shape == (501, 1, 13)
    np.testing.assert_allclose(single.y, batch.y[:, 0], rtol=READABLE_VS_BATCHED, atol=READABLE_VS_BATCHED)


@pytest.mark.parametrize("variant", ["course", "expmap_gyro", "leapfrog", "rk4"])
def test_zero_angular_velocity_and_zero_length_spring_are_fine(variant):
    # ω = 0 (exp map of a zero rotation) and a spring whose attachment sits on its anchor (L = 0).
    from reference_sim.body import RigidBody
    from reference_sim.forces import ForceModel, Spring
    from reference_sim.state import Problem, State
    p = Problem(RigidBody(1.0, [1.0, 2.0, 3.0]), ForceModel(springs=(Spring(np.zeros(3), np.zeros(3), 10.0, 0.5),)),
                State(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(3)))
    run = simulate(p, variant, 1e-2, 10)
    assert run.diverged_at_s is None and np.all(run.y[-1] == p.initial_packed())


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_numpy_soa_backend_equals_batched(variant):
    problem = coupled_problem((0.99, 0.995))
    rng = np.random.default_rng(11)
    y = np.tile(problem.initial_packed(), (6, 1))
    y[:, 10:13] += rng.normal(scale=0.5, size=(6, 3))
    y[0, 0:3] = problem.forces.springs[0].anchor_W - np.array([0.1, 0.0, 0.05])  # L = 0 at identity... near it
    cols = [np.ascontiguousarray(c) for c in y.T]
    stepper = ScalarStepper(problem, variant, 2e-3, backend="numpy")
    step_b = get_step(variant)
    for _ in range(100):
        y = step_b(problem, y, 2e-3)
        cols = stepper.step(cols)
    np.testing.assert_allclose(np.stack(cols, axis=-1), y, rtol=READABLE_VS_BATCHED, atol=READABLE_VS_BATCHED)


def test_the_if_flags_follow_every_setting_including_one_changed_after_construction():
    # the flags only skip contributions that are zero; a stale False would silently drop a planted bug's
    # drag, decay or body torque (tests/mutants.py changes them after __init__)
    from reference_sim.body import RigidBody
    from reference_sim.forces import ForceModel, Torque
    from reference_sim.state import Problem, State
    p = Problem(RigidBody(1.0, [1.0, 2.0, 3.0]), ForceModel(torques=(Torque(np.array([0.0, 0.0, 0.5]), "body"),)),
                State(np.zeros(3), np.ones(3), np.array([1.0, 0, 0, 0]), np.array([0.1, 0.2, 0.3])))
    s = ScalarStepper(p, "rk4", 0.01)
    assert s.has_body_torque and not s.has_drag and not s.has_velocity_decay and not s.has_angular_decay
    y = p.initial_packed().tolist()
    plain = s.rhs(y)
    s.c, s.kv, s.kw, s.tau_B = 0.3, 0.2, 0.1, [0.0, 0.0, 0.0]
    assert s.has_drag and s.has_velocity_decay and s.has_angular_decay and not s.has_body_torque
    changed = s.rhs(y)
    assert changed[3] == pytest.approx(plain[3] - 0.3 * 1.0 - 0.2 * 1.0)   # drag −c v and decay −k v on v_x
    assert changed[10] != plain[10]

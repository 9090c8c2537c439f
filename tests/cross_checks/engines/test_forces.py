"""cross_checks.engines.forces: the weight an engine that applies gravity itself must not get again."""
import numpy as np

from cross_checks.engines import forces


def test_weight_is_mass_times_gravity_in_world_axes():
    from cross_checks.scenario import load_scenario
    sc = load_scenario("projectile")
    want = sc.problem.body.mass_kg * np.asarray(sc.problem.forces.gravity_W)
    assert forces.weight_W(sc).tolist() == want.tolist()


def test_minus_weight_takes_the_weight_off_the_force_only():
    wrench = forces.minus_weight(lambda y: (1.0, 2.0, 3.0 + y[0], 4.0, 5.0, 6.0), np.array([0.5, 0.0, -9.75]))
    assert wrench([0.25]) == (0.5, 2.0, 13.0, 4.0, 5.0, 6.0)

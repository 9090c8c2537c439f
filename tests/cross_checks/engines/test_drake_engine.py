"""The Drake adapter (cross_checks.engines.drake_engine): every convention it relies on, pinned on Drake
itself (docs/engine_conventions.md), its force and decay paths against hand-derived steps, its orders, and the
planted mistakes it catches."""
import dataclasses
import math

import numpy as np
import pytest

from tests.helpers import tolerances as tol

pytest.importorskip("pydrake", reason="drake is not installed (pip install -e '.[drake]')")

from cross_checks.engines import drake_engine as de  # noqa: E402
from cross_checks.engines.forces import stage_force_torque  # noqa: E402
from cross_checks.scenario import load_scenario  # noqa: E402
from reference_sim.ground_truth import ground_truth  # noqa: E402
from reference_sim.quaternion import geodesic_angle, matrix_from_quat, quat_exp, quat_mul  # noqa: E402
from tests.helpers.scenarios import scenario_from_parts  # noqa: E402

Q_TILT = np.array([0.9, 0.1, 0.3, -0.2]) / np.linalg.norm([0.9, 0.1, 0.3, -0.2])
FULL_INERTIA = "mass = 2.0\ninertia = [[2.0, 0.1, 0.05], [0.1, 3.0, -0.2], [0.05, -0.2, 4.0]]"


def _order(dts, errs):
    return float(np.polyfit(np.log(dts), np.log(errs), 1)[0])


def test_version_is_the_pinned_release():
    assert de.version() == "1.51.1"


# --- conventions -------------------------------------------------------------------------------------

def test_positions_are_the_quaternion_w_x_y_z_then_the_position():
    from pydrake.common.eigen_geometry import Quaternion
    from pydrake.math import RigidTransform
    model = de.DrakeModel(scenario_from_parts(), "runge_kutta3")
    model.plant.SetFreeBodyPose(model.context, model.body,
                                RigidTransform(Quaternion(*Q_TILT), [1.0, 2.0, 3.0]))
    np.testing.assert_allclose(model.plant.GetPositions(model.context),
                               np.r_[Q_TILT, 1.0, 2.0, 3.0], rtol=0, atol=1e-15)
    y = np.r_[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, Q_TILT, 0.1, 0.2, 0.3]
    np.testing.assert_array_equal(de.dkw.from_drake_state(de.dkw.to_drake_state(y)), y)


def test_velocities_are_angular_first_both_in_world_axes():
    from pydrake.multibody.math import SpatialVelocity
    model = de.DrakeModel(scenario_from_parts(), "runge_kutta3")
    model.set_state(np.r_[np.zeros(6), Q_TILT, np.zeros(3)])
    model.plant.SetFreeBodySpatialVelocity(model.context, model.body,
                                           SpatialVelocity(w=[0.1, 0.2, 0.3], v=[4.0, 5.0, 6.0]))
    # V_WB expressed in WORLD axes although the body is tilted: the generalized velocities are [ω_W, v_W]
    np.testing.assert_array_equal(model.plant.GetVelocities(model.context), [0.1, 0.2, 0.3, 4.0, 5.0, 6.0])


def test_a_yawed_body_spinning_about_body_x_turns_about_world_y():
    # 90° yaw: body x is world y. A torque-free spin about a principal axis stays there, ω_W constant,
    # and the attitude turns about WORLD y: q(t) = exp(ω_W t) ⊗ q0
    sq = math.sqrt(0.5)
    sc = scenario_from_parts(initial=f"orientation = [{sq!r}, 0.0, 0.0, {sq!r}]\n"
                                     "angular_velocity = [0.0, 2.0, 0.0]",
                             dt=0.01, duration=0.5)
    run = de.simulate(sc, "runge_kutta3", 0.01, 50)
    np.testing.assert_allclose(run.y[-1, 10:13], [0.0, 2.0, 0.0], atol=1e-12)
    expected = quat_mul(quat_exp(np.array([0.0, 2.0, 0.0]) * 0.5), np.array([sq, 0.0, 0.0, sq]))
    assert geodesic_angle(run.y[-1, 6:10], expected) < tol.DRAKE_SPIN_RK3


def test_generalized_forces_are_the_world_torque_then_the_world_force_at_the_com():
    sc = scenario_from_parts(body=FULL_INERTIA, initial=f"orientation = {Q_TILT.tolist()}",
                             forces='gravity = [0.0, 0.0, -9.81]\n'
                                    '[[forces.torque]]\n'
                                    'torque = [0.3, -0.2, 0.5]\n'
                                    'frame = "world"\n'
                                    '[[forces.point]]\nforce = [1.0, 2.0, 3.0]\nframe = "world"')
    model = de.DrakeModel(sc, "runge_kutta3")
    model.set_state(sc.problem.initial_packed())
    vdot = model.plant.EvalTimeDerivatives(model.context).get_generalized_velocity().CopyToVector()
    R = matrix_from_quat(Q_TILT)
    I_W = R @ sc.problem.body.inertia_B @ R.T
    np.testing.assert_allclose(vdot[0:3], np.linalg.solve(I_W, [0.3, -0.2, 0.5]),
                               rtol=tol.DRAKE_DERIVATIVE_REL)
    np.testing.assert_allclose(vdot[3:6], np.array([1.0, 2.0, 3.0]) / 2.0 + [0.0, 0.0, -9.81],
                               rtol=tol.DRAKE_DERIVATIVE_REL)


def test_the_inertia_is_about_the_com_in_body_axes_full_tensors_included():
    sc = scenario_from_parts(body=FULL_INERTIA)
    model = de.DrakeModel(sc, "runge_kutta3")
    M = model.body.CalcSpatialInertiaInBodyFrame(model.context)
    assert M.get_mass() == 2.0
    np.testing.assert_array_equal(M.get_com(), np.zeros(3))
    np.testing.assert_allclose(M.CalcRotationalInertia().CopyToFullMatrix3(), sc.problem.body.inertia_B,
                               rtol=0, atol=1e-15)


def test_the_gyroscopic_term_is_drakes_own():
    # torque-free full-tensor tumble: ω̇_W = −I_W⁻¹ (ω × I_W ω), nothing of it from rbcheck
    sc = scenario_from_parts(body=FULL_INERTIA,
                             initial=f"orientation = {Q_TILT.tolist()}\nangular_velocity = [0.4, 1.5, -0.7]")
    model = de.DrakeModel(sc, "runge_kutta3")
    model.set_state(sc.problem.initial_packed())
    vdot = model.plant.EvalTimeDerivatives(model.context).get_generalized_velocity().CopyToVector()
    R = matrix_from_quat(Q_TILT)
    I_W = R @ sc.problem.body.inertia_B @ R.T
    w = sc.problem.initial.w_W
    np.testing.assert_allclose(vdot[0:3], -np.linalg.solve(I_W, np.cross(w, I_W @ w)),
                               rtol=tol.DRAKE_DERIVATIVE_REL)


def test_drake_does_not_renormalise_the_quaternion_and_the_recorded_one_is_unit():
    sc = load_scenario("tennis_racket")
    model = de._model(sc, "semi_explicit_euler", 0.01)
    model.set_state(sc.problem.initial_packed())
    for k in range(1, 201):
        model.simulator.AdvanceTo(k * 0.01)
    norm = np.linalg.norm(model.drake_state()[0:4])
    assert norm - 1.0 > tol.DRAKE_QUATERNION_DRIFT_MIN, norm   # linear q update: |q| grows
    run = de.simulate(sc, "semi_explicit_euler", 0.01, 200)
    np.testing.assert_allclose(np.linalg.norm(run.y[:, 6:10], axis=1), 1.0, atol=1e-15)


def test_a_fixed_step_is_one_step_per_target_only_with_the_slack(monkeypatch):
    sc = load_scenario("tennis_racket")

    def steps_for(n):
        model = de._model(sc, "semi_explicit_euler", 1e-3)
        model.set_state(sc.problem.initial_packed())
        for k in range(1, n + 1):
            model.simulator.AdvanceTo(k * 1e-3)
        return model.integrator.get_num_steps_taken()

    assert steps_for(2000) == 2000
    monkeypatch.setattr(de.dkw, "FIXED_STEP_SLACK", 0.0)   # the world's (worlds/drake.py)
    assert steps_for(2000) > 2000          # the trap: a target one rounding beyond Δt is a step and a sliver


# --- forces and decay --------------------------------------------------------------------------------

def test_decay_is_the_damping_rate_in_the_right_hand_side_not_a_factor_per_step():
    sc = scenario_from_parts(initial="velocity = [1.0, -2.0, 0.5]\nangular_velocity = [0.0, 0.0, 3.0]",
                             forces="velocity_decay = 0.99\nangular_velocity_decay = 0.995", dt=0.01)
    kv, kw = -math.log(0.99) / 0.01, -math.log(0.995) / 0.01
    y0 = sc.problem.initial_packed()
    y1 = de.one_step(sc, "semi_explicit_euler", 0.01, y0[None])[0]
    # semi-explicit Euler of v̇ = −k v: v1 = (1 − kΔt) v0 (not e^{−kΔt} v0, nor the course's 0.99 v0)
    np.testing.assert_allclose(y1[3:6], (1 - kv * 0.01) * y0[3:6], rtol=1e-14)
    np.testing.assert_allclose(y1[10:13], (1 - kw * 0.01) * y0[10:13], rtol=1e-14)
    assert abs(y1[3] - 0.99 * y0[3]) > 1e-6
    # RK3 of the same linear ODE: the cubic Taylor polynomial of e^{−kΔt}
    z = kv * 0.01
    y1 = de.one_step(sc, "runge_kutta3", 0.01, y0[None])[0]
    np.testing.assert_allclose(y1[3:6], (1 - z + z * z / 2 - z ** 3 / 6) * y0[3:6], rtol=1e-14)


SP_LADDER = [0.004, 0.002, 0.001]


def _final_errors(sc, variant, ladder, T, simulate=None):
    gt = ground_truth(sc.problem, np.array([0.0, T]))[-1]
    out = []
    for h in ladder:
        y = (simulate or de.simulate)(sc, variant, h, int(round(T / h))).y[-1]
        out.append(max(np.linalg.norm(y[0:3] - gt[0:3]), geodesic_angle(gt[6:10], y[6:10])))
    return np.array(out)


@pytest.mark.parametrize("variant, order", [("runge_kutta2", 2.0), ("runge_kutta3", 3.0)])
def test_multi_stage_schemes_keep_their_order_with_state_dependent_forces(variant, order):
    errs = _final_errors(load_scenario("spring_pendulum"), variant, SP_LADDER, 1.0)
    assert abs(_order(SP_LADDER, errs) - order) < tol.DRAKE_ORDER_TOL, errs


def _forces_held_over_the_step(sc, variant, dt, n):
    """The planted mistake: the scenario's forces evaluated at the start of each step and held over it
    (a fixed input value per step) instead of at every stage."""
    fm = sc.problem.forces
    bare = dataclasses.replace(sc, problem=dataclasses.replace(
        sc.problem,
        forces=dataclasses.replace(fm, springs=(), point_forces=(), torques=(), linear_drag_N_s_per_m=0.0)))
    model = de._model(bare, variant, dt)
    y = sc.problem.initial_packed()
    model.set_state(y)
    port = model.plant.get_applied_generalized_force_input_port()
    weight = sc.problem.body.mass_kg * np.asarray(fm.gravity_W)
    out = [y]
    for k in range(1, n + 1):
        f, tau = stage_force_torque(sc, out[-1])
        port.FixValue(model.context, np.r_[tau, f - weight])
        model.simulator.AdvanceTo(k * dt)
        out.append(model.state())
    from reference_sim.simulate import Run
    return Run(dt * np.arange(n + 1), np.array(out))


def test_forces_held_over_the_step_cost_rk3_its_order():
    errs = _final_errors(load_scenario("spring_pendulum"), "runge_kutta3", SP_LADDER, 1.0,
                         simulate=_forces_held_over_the_step)
    assert abs(_order(SP_LADDER, errs) - 1.0) < tol.DRAKE_ORDER_TOL, errs


# --- runs ------------------------------------------------------------------------------------------------

def test_a_blow_up_is_reported_as_divergence_with_the_rows_before_it():
    # k/m = 1e6: semi-explicit Euler is unstable for ωΔt > 2; here ωΔt = 10, |x| grows ~100× per step
    sc = scenario_from_parts(initial="position = [0.1, 0.0, 0.0]",
                             forces="[[forces.spring]]\nanchor = [0.0, 0.0, 0.0]\nattach = [0.0, 0.0, 0.0]\n"
                                    "stiffness = 1e6\nrest_length = 0.0", dt=0.01, duration=1.0)
    for variant in ("semi_explicit_euler", "runge_kutta3"):
        run = de.simulate(sc, variant, 0.01, 100)
        assert run.diverged_at_s is not None and 0.0 < run.diverged_at_s < 0.2
        # Drake then refuses to step the blown-up state ("Detected NaN in applied generalized force input
        # port"): a consequence, not a cause, left out of the words (DrakeWorld.first_cause_only)
        assert run.message == f"diverged at t = {run.diverged_at_s:.6g} s (state beyond 1e+08)"
        assert len(run.t_s) == round(run.diverged_at_s / 0.01) and np.all(np.abs(run.y) <= 1e8)


def test_tennis_racket_rk3_matches_the_closed_form():
    from cross_checks.scenario.references import reference_solution
    sc = load_scenario("tennis_racket")
    run = de.simulate(sc, "runge_kutta3", 1e-3, sc.n_steps(1e-3))
    ref, _ = reference_solution(sc, run.t_s)
    assert np.max(geodesic_angle(ref[:, 6:10], run.y[:, 6:10])) < tol.DRAKE_RK3_TENNIS_RAD


def test_drake_refusing_to_go_on_is_divergence_at_that_step(monkeypatch):
    real = de._model

    class Refusing:
        def __init__(self, sim):
            self.sim = sim

        def __getattr__(self, name):
            return getattr(self.sim, name)

        def AdvanceTo(self, t):
            if t > 0.065:
                raise RuntimeError("Detected NaN in applied generalized force input port.\nmore words")
            self.sim.AdvanceTo(t)

    def model(*args):
        m = real(*args)
        m.simulator = Refusing(m.simulator)
        return m

    monkeypatch.setattr(de, "_model", model)
    run = de.simulate(load_scenario("spring_pendulum"), "runge_kutta2", 0.01, 50)
    assert run.diverged_at_s == pytest.approx(0.07) and len(run.t_s) == 7
    assert run.message == ("diverged at t = 0.07 s "
                           "(Drake: Detected NaN in applied generalized force input port.)")


def test_a_row_whose_step_drake_refuses_comes_back_non_finite_in_one_step(monkeypatch):
    sc = load_scenario("spring_pendulum")
    rows = de.simulate(sc, "runge_kutta2", 0.01, 3).y[:3]
    clean = de.one_step(sc, "runge_kutta2", 0.01, rows)
    real, built = de._model, []

    class Refusing:
        def __init__(self, sim):
            self.sim = sim

        def __getattr__(self, name):
            return getattr(self.sim, name)

        def AdvanceTo(self, t):
            raise RuntimeError("Detected NaN in applied generalized force input port.")

    def model(*args):   # the second body of the world (row 1) is refused
        m = real(*args)
        built.append(m)
        if len(built) == 2:
            m.simulator = Refusing(m.simulator)
        return m

    monkeypatch.setattr(de, "_model", model)
    got = de.one_step(sc, "runge_kutta2", 0.01, rows)
    assert np.all(np.isnan(got[1]))
    np.testing.assert_array_equal(got[[0, 2]], clean[[0, 2]])

"""Integrators: each scheme has its order (the batched path against the readable one: test_readable.py)."""
import numpy as np
import pytest

from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel, PointForce, Spring, Torque
from reference_sim.ground_truth import ground_truth
from reference_sim.integrators import VARIANTS, get_step
from reference_sim.quaternion import geodesic_angle, quat_exp, quat_normalize
from reference_sim.simulate import simulate
from reference_sim.state import Problem, State
from tests.helpers.tolerances import COURSE_NONCONVERGENCE_MIN_RAD, ORDER_TOL


def coupled_problem(decay=(1.0, 1.0)):
    """Every force type at once: springs off the COM, drag, body and world point forces, torques."""
    fm = ForceModel(
        gravity_W=np.array([0.0, 0.0, -9.81]), linear_drag_N_s_per_m=0.3,
        velocity_decay=decay[0], angular_velocity_decay=decay[1], decay_dt_s=2e-3,
        springs=(Spring(np.array([0.0, 0.0, 1.0]), np.array([0.1, 0.0, 0.05]), 40.0, 0.5),),
        point_forces=(PointForce(np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.1, 0.0]), "world"),
                      PointForce(np.array([0.0, 0.5, 0.0]), np.array([0.0, 0.0, 0.2]), "body")),
        torques=(Torque(np.array([0.0, 0.0, 0.2]), "body"), Torque(np.array([0.1, 0.0, 0.0]), "world")),
    )
    body = RigidBody(1.5, [[0.05, 0.01, 0.0], [0.01, 0.06, 0.005], [0.0, 0.005, 0.08]])
    init = State(np.array([0.3, 0.0, 0.4]), np.array([0.0, 0.5, 0.0]), quat_normalize([1.0, 0.2, -0.1, 0.3]),
                 np.array([0.5, -1.0, 2.0]))
    return Problem(body, fm, init)


@pytest.mark.parametrize("variant", ["course", "course_gyro", "expmap_gyro"])
def test_course_type_batched_is_bit_identical_to_single_body_calls(variant):
    # The same arithmetic, one body at a time or four at once: exactly equal.
    problem = coupled_problem((0.99, 0.995))
    y = np.tile(problem.initial_packed(), (4, 1)) * np.array([[1.0], [1.01], [0.99], [1.02]])
    step = get_step(variant)
    batched = step(problem, y, 1e-3)
    single = np.array([step(problem, row, 1e-3) for row in y])
    assert np.array_equal(batched, single)


def test_constant_spin_about_w_at_speed_w_course():
    # The course's sanity check: torque-free, isotropic body, constant ω -> rotation about ω/|ω| by |ω| t
    # (up to the course update's known phase lag, checked in test_analytic).
    w = np.array([0.3, -1.2, 0.8])
    problem = Problem(RigidBody(1.0, [1.0, 1.0, 1.0]), ForceModel(),
                      State(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), w))
    run = simulate(problem, "course", 1e-4, 10000)
    q_exact = quat_exp(run.t_s[:, None] * w)
    np.testing.assert_allclose(run.y[:, 10:13], np.tile(w, (len(run.t_s), 1)), atol=0)
    assert np.max(geodesic_angle(q_exact, run.y[:, 6:10])) < 1e-8  # lag T|ω|³Δt²/12 = 3e-10


def test_gravity_alone_changes_v_not_w():
    problem = Problem(RigidBody(1.0, [1.0, 2.0, 3.0]), ForceModel(gravity_W=np.array([0, 0, -9.81])),
                      State(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(3)))
    for v in VARIANTS:
        run = simulate(problem, v, 1e-2, 50)
        assert np.all(run.y[:, 10:13] == 0.0), v
        assert run.y[-1, 5] < 0, v


def _orders(errs, dts):
    return np.polyfit(np.log(dts), np.log(errs), 1)[0]


def translation_problem():
    # Zero-length spring at the COM + gravity: harmonic oscillator, closed form below.
    k, m = 40.0, 1.0
    fm = ForceModel(gravity_W=np.array([0, 0, -9.81]),
                    springs=(Spring(np.array([0, 0, 1.0]), np.zeros(3), k, 0.0),))
    return Problem(RigidBody(m, [0.05, 0.05, 0.05]), fm,
                   State(np.array([0.2, -0.1, 0.5]), np.array([0, 0.3, 0]),
                         np.array([1.0, 0, 0, 0]), np.zeros(3)))


def harmonic_exact(problem, t):
    s = problem.forces.springs[0]
    k, m = s.stiffness_N_per_m, problem.body.mass_kg
    eq = s.anchor_W + m * problem.forces.gravity_W / k
    om = np.sqrt(k / m)
    x0, v0 = problem.initial.x_W - eq, problem.initial.v_W
    return eq + x0 * np.cos(om * t) + v0 / om * np.sin(om * t)


def rotation_problem():
    # Asymmetric torque-free body: compared with the DOP853 ground truth.
    return Problem(RigidBody(1.0, [1.0, 2.0, 3.0]), ForceModel(),
                   State(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), np.array([0.5, 1.0, 0.3])))


# dt ladders per expected order: asymptotic (ω Δt ≤ 0.13 for the oscillator's ω = 6.3 rad/s) and, for
# RK4, errors kept above the ground truth's ~1e-12 floor.
LADDERS = {1: [4e-3, 2e-3, 1e-3, 5e-4], 2: [8e-3, 4e-3, 2e-3, 1e-3], 4: [2e-2, 1e-2, 5e-3, 2.5e-3]}
LADDERS_ROTATION = {**LADDERS, 4: [1e-1, 5e-2, 2.5e-2, 1.25e-2]}


@pytest.mark.parametrize("variant", ["explicit_euler", "implicit_euler", "course", "expmap_gyro", "midpoint",
                                     "leapfrog", "rk4", "jolt_gyro", "buss_augmented", "dlm_splitting",
                                     "lp_midpoint", "moser_veselov"])
def test_global_order_translation(variant):
    problem, T = translation_problem(), 1.0
    dts = LADDERS[VARIANTS[variant].order]
    errs = []
    for dt in dts:
        run = simulate(problem, variant, dt, int(round(T / dt)))
        errs.append(np.linalg.norm(run.y[-1, 0:3] - harmonic_exact(problem, T)))
    assert abs(_orders(errs, dts) - VARIANTS[variant].order) < ORDER_TOL, errs


@pytest.mark.parametrize("variant",
                         ["explicit_euler", "implicit_euler", "course_gyro", "expmap_gyro", "midpoint",
                          "leapfrog", "rk4", "implicit_gyro_body", "implicit_gyro_world",
                          "explicit_gyro_clamped", "jolt_gyro", "buss_augmented", "dlm_splitting",
                          "lp_midpoint", "moser_veselov"])
def test_global_order_rotation(variant):
    problem, T = rotation_problem(), 1.0
    dts = LADDERS[VARIANTS[variant].order]
    truth = ground_truth(problem, np.array([0.0, T]))[-1]
    dts = LADDERS_ROTATION[VARIANTS[variant].order]
    errs = []
    for dt in dts:
        run = simulate(problem, variant, dt, int(round(T / dt)))
        errs.append(float(geodesic_angle(truth[6:10], run.y[-1, 6:10])))
    assert abs(_orders(errs, dts) - VARIANTS[variant].order) < ORDER_TOL, errs


@pytest.mark.parametrize("variant", ["explicit_euler", "implicit_euler", "course", "expmap_gyro"])
def test_euler_local_error_is_second_order(variant):
    # One step from the exact initial state: error O(Δt²), as the course teaches (order 2 ± 0.1).
    problem = translation_problem()
    dts = np.array([1e-2, 5e-3, 2.5e-3, 1.25e-3])
    errs = [np.linalg.norm(simulate(problem, variant, dt, 1).y[-1, 0:3] - harmonic_exact(problem, dt))
            for dt in dts]
    assert abs(_orders(errs, dts) - 2.0) < ORDER_TOL, errs


def test_course_does_not_converge_on_tennis_racket_but_gyro_variants_do():
    from cross_checks.scenario import load_scenario
    from cross_checks.scenario.references import reference_solution
    sc = load_scenario("tennis_racket")
    y_ref, _ = reference_solution(sc, np.array([0.0, sc.duration_s]))
    for variant in ["course", "course_gyro", "expmap_gyro"]:
        errs = []
        for dt in sc.dt_ladder_s:
            run = simulate(sc.problem, variant, dt, sc.n_steps(dt))
            errs.append(float(geodesic_angle(y_ref[-1, 6:10], run.y[-1, 6:10])))
        if variant == "course":
            assert min(errs) > COURSE_NONCONVERGENCE_MIN_RAD, errs
        else:
            assert abs(_orders(errs, sc.dt_ladder_s) - 1.0) < ORDER_TOL, (variant, errs)


# --- velocity decay: the course's γ at its own step, a rate k = −ln γ / dt everywhere ---------------

def decay_problem(dt_course=0.01):
    """Gravity, velocity decay 0.99 and angular decay 0.995 per course step of 0.01 s, spinning about a
    principal axis: the continuously damped motion has a closed form (drag with c = m k_v; ω e^{−k_ω t})."""
    fm = ForceModel(gravity_W=np.array([0.0, 0.0, -9.81]), velocity_decay=0.99, angular_velocity_decay=0.995,
                    decay_dt_s=dt_course)
    return Problem(RigidBody(2.0, [0.2, 0.3, 0.4]), fm,
                   State(np.zeros(3), np.array([1.0, 0.5, 3.0]),
                         np.array([1.0, 0, 0, 0]), np.array([0.0, 0.0, 2.0])))


def decay_exact(problem, t):
    from reference_sim.analytic import linear_drag
    k_v, k_w = problem.forces.decay_rates_per_s()
    m = problem.body.mass_kg
    x, v = linear_drag(m, m * k_v, problem.initial.x_W, problem.initial.v_W,
                       problem.forces.gravity_W, np.array([t]))
    w0 = problem.initial.w_W
    q = quat_exp(-np.expm1(-k_w * t) / k_w * w0)          # angle ∫ω dt = ω0 (1 − e^{−kt}) / k
    return np.concatenate([x[0], v[0], q, w0 * np.exp(-k_w * t)])


@pytest.mark.parametrize("variant", ["course", "course_gyro", "expmap_gyro"])
def test_course_variants_at_the_scenarios_own_step_apply_exactly_the_course_gamma(variant):
    # v ← γ (v + Δt g), ω ← γ_ω ω (spin about a principal axis): the course's step, bit for bit, in the
    # definition and in the compiled run.
    problem, h = decay_problem(), 0.01
    y0 = problem.initial_packed()
    for y1 in (get_step(variant)(problem, y0, h), simulate(problem, variant, h, 1).y[1]):
        assert np.array_equal(y1[3:6], 0.99 * (y0[3:6] + h * problem.forces.gravity_W))
        assert np.array_equal(y1[10:13], 0.995 * y0[10:13])


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_every_variant_converges_at_its_order_to_the_continuously_damped_motion(variant):
    problem, T = decay_problem(), 1.0
    exact = decay_exact(problem, T)
    p = VARIANTS[variant].order
    dts = {1: [4e-2, 2e-2, 1e-2, 5e-3], 2: [4e-2, 2e-2, 1e-2, 5e-3], 4: [1e-1, 5e-2, 2.5e-2, 1.25e-2]}[p]
    errs = {"v": [], "w": [], "q": []}
    for dt in dts:
        y = simulate(problem, variant, dt, int(round(T / dt))).y[-1]
        errs["v"].append(np.linalg.norm(y[3:6] - exact[3:6]))
        errs["w"].append(np.linalg.norm(y[10:13] - exact[10:13]))
        errs["q"].append(float(geodesic_angle(exact[6:10], y[6:10])))
    course_type = variant in COURSE_TYPE
    for key in ("v", "q") if course_type else ("v", "w", "q"):
        assert abs(_orders(errs[key], dts) - p) < ORDER_TOL, (key, errs[key])
    if course_type:  # e^{−k_ω Δt} per step is the exact decay of a torque-free principal-axis spin:
        # exact up to one rounding of ε|ω0| per step
        assert max(errs["w"]) <= round(T / dts[-1]) * 2.2e-16 * np.linalg.norm(problem.initial.w_W), errs["w"]


#: The course-type schemes: decay e^{−kΔt} after the velocity update (the engines' gyroscopic steps are such
#: steps too: reference_sim.integrators, "the gyroscopic steps of shipping engines").
COURSE_TYPE = ("course", "course_gyro", "expmap_gyro", "implicit_gyro_body", "implicit_gyro_world",
               "explicit_gyro_clamped", "jolt_gyro")


def test_decay_applied_twice_or_left_out_does_not_converge():
    # What the velocity_decay gate catches: the frame-rate independent decay converges, the others do not.
    problem, T = decay_problem(), 1.0
    exact = decay_exact(problem, T)
    double = Problem(problem.body, ForceModel(gravity_W=problem.forces.gravity_W, velocity_decay=0.99 ** 2,
                                              angular_velocity_decay=0.995 ** 2, decay_dt_s=0.01),
                     problem.initial)
    none = Problem(problem.body, ForceModel(gravity_W=problem.forces.gravity_W), problem.initial)
    for wrong in (double, none):
        errs = [np.linalg.norm(simulate(wrong, "rk4", dt, int(round(T / dt))).y[-1, 3:6] - exact[3:6])
                for dt in (2e-2, 1e-2, 5e-3)]
        assert min(errs) > 0.1 * max(errs) and min(errs) > 1e-2, errs

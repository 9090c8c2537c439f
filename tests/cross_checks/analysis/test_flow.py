"""cross_checks.analysis.flow against closed forms and hand-derived numbers (not against itself)."""
import numpy as np
import pytest

from cross_checks.analysis.flow import (
    distances,
    error_growth,
    exact_flow,
    flow_rhs,
    local_allowances,
    majorant,
    motion_rate,
    rk4_flow,
    spring_turn_rate,
)
from cross_checks.core import tolerances as tol
from cross_checks.core.trajectory import Trajectory
from cross_checks.gates.check.input import prepare_input
from cross_checks.scenario import load_scenario, parse_scenario
from reference_sim import analytic
from reference_sim.quaternion import quat_exp, quat_normalize
from reference_sim.state import Q, W
from tests.helpers.scenarios import scenario_from_parts

QUANTITIES = ("position", "velocity", "orientation", "angular_velocity")


def _random_rotation_states(n, seed=0, speed=3.0):
    rng = np.random.default_rng(seed)
    y = np.zeros((n, 13))
    y[:, Q] = quat_normalize(rng.normal(size=(n, 4)))
    y[:, W] = speed * rng.normal(size=(n, 3))
    return y


def test_the_exact_flow_matches_the_jacobi_closed_form_from_arbitrary_states():
    sc = load_scenario("tennis_racket")                     # I = 1, 2, 3: torque-free, asymmetric
    y0 = _random_rotation_states(40)
    span = np.full(40, 0.01)
    fl = exact_flow(sc, y0, span)
    for k in range(40):
        q_ref, w_ref = analytic.torque_free(sc.problem.body.inertia_B, y0[k, Q], y0[k, W], np.array([0.01]))
        ref = y0[k].copy()
        ref[Q], ref[W] = q_ref[0], w_ref[0]
        d = distances(fl.y_end[k:k + 1], ref[None, :], ("orientation", "angular_velocity"))
        # the flow is as accurate as it says (closed form good to ~1e-12), and far below any allowance
        assert d["orientation"][0] <= 10 * fl.error["orientation"][k] + 1e-12
        assert (d["angular_velocity"][0]
                <= 10 * fl.error["angular_velocity"][k] + 1e-12 * np.linalg.norm(y0[k, W]))
        assert d["angular_velocity"][0] <= 1e-3 * tol.CHECK_LOCAL_C * 0.01 ** 2 * fl.M2["angular_velocity"][k]


def test_the_exact_flow_of_a_projectile_is_the_parabola():
    sc = load_scenario("projectile")
    y0 = np.zeros((3, 13))
    y0[:, 3:6] = [[1, 2, 3], [0, 0, 0], [-5, 1, 0]]
    y0[:, 6] = 1.0
    fl = exact_flow(sc, y0, np.array([0.01, 0.1, 1.0]))
    for k, h in enumerate((0.01, 0.1, 1.0)):
        x, v = analytic.projectile(y0[k, 0:3], y0[k, 3:6], sc.problem.forces.gravity_W, np.array([h]))
        np.testing.assert_allclose(fl.y_end[k, 0:3], x[0], atol=1e-14)
        np.testing.assert_allclose(fl.y_end[k, 3:6], v[0], atol=1e-14)


def test_the_majorant_is_the_hand_derived_second_derivative_of_an_oscillator():
    """x'' = a = g − (k/m)(x − anchor): M2_x = |a|; v'' = −(k/m) v: M2_v = (k/m)|v| (one block)."""
    sc = load_scenario("spring_oscillator")                 # k = 40, m = 1, anchor (0, 0, 1), g = −9.81 z
    y = np.zeros((2, 13))
    y[:, 0:3] = [[0.2, -0.1, 0.5], [1.0, 0.0, 0.0]]
    y[:, 3:6] = [[0.0, 0.3, 0.0], [1.0, -2.0, 0.5]]
    y[:, 6] = 1.0
    F = flow_rhs(sc)
    M2 = majorant(F, y, motion_rate(sc, y))
    a = np.array([0, 0, -9.81]) - 40.0 * (y[:, 0:3] - [0, 0, 1])
    np.testing.assert_allclose(M2["position"], np.linalg.norm(a, axis=1), rtol=1e-8)
    np.testing.assert_allclose(M2["velocity"], 40.0 * np.linalg.norm(y[:, 3:6], axis=1), rtol=1e-6)


def test_the_majorant_bounds_the_true_second_derivative_of_a_tumbling_body():
    sc = load_scenario("tumbling_box")
    p = sc.problem
    t = np.linspace(0.0, 3.0, 61)
    h = 1e-4
    tt = np.concatenate([t - h, t, t + h])
    q, w = analytic.torque_free(p.body.inertia_B, p.initial.q_WB, p.initial.w_W, tt)
    q = q.reshape(3, -1, 4)
    w = w.reshape(3, -1, 3)
    for qq in (q[0], q[2]):                                  # same hemisphere as the middle sample
        qq *= np.sign(np.sum(qq * q[1], axis=1))[:, None]
    y = np.zeros((len(t), 13))
    y[:, Q], y[:, W] = q[1], w[1]
    M2 = majorant(flow_rhs(sc), y, motion_rate(sc, y))
    w_dd = np.linalg.norm(w[0] - 2 * w[1] + w[2], axis=1) / h ** 2
    q_dd = 2 * np.linalg.norm(q[0] - 2 * q[1] + q[2], axis=1) / h ** 2
    assert np.all(M2["angular_velocity"] >= w_dd * (1 - 1e-4))
    assert np.all(M2["orientation"] >= q_dd * (1 - 1e-4))


def _traj_of(rows_t, y):
    return Trajectory(np.asarray(rows_t, float), y, {"quantities_present": list(QUANTITIES)})


def test_one_euler_step_under_gravity_uses_half_its_allowance():
    """Explicit Euler: x1 = x0 + h v0, exact x0 + h v0 + ½ h² g: defect ½ h² |g|; allowance C h² |g|."""
    sc = load_scenario("projectile")
    h = 0.01
    y = np.zeros((2, 13))
    y[:, 6] = 1.0
    y[0, 3:6] = [1.0 / 3.0, 2.0 / 7.0, 3.0 / 11.0]         # full-precision values, as a simulator writes them
    y[1, 0:3] = h * y[0, 3:6]
    y[1, 3:6] = y[0, 3:6] + h * sc.problem.forces.gravity_W
    inp = prepare_input(_traj_of([0.0, h], y), sc, "e.csv")
    fl = exact_flow(sc, y[:1], inp.span_s)
    al = local_allowances(inp, y[:1], fl.M2, fl.rate, fl.roundoff)
    d = distances(y[1:], fl.y_end)
    assert d["position"][0] == pytest.approx(0.5 * h ** 2 * 9.81, rel=1e-9)
    assert d["position"][0] / al.total["position"][0] == pytest.approx(0.5 / tol.CHECK_LOCAL_C, rel=1e-6)


def test_ten_symplectic_euler_steps_per_row_use_half_the_decimated_allowance():
    """D steps of h: x_D = x0 + Δ v0 + g h² D(D+1)/2 against x0 + Δ v0 + ½ g Δ²: defect ½ g h Δ."""
    sc = load_scenario("projectile")
    h, D = 0.001, 10
    g = sc.problem.forces.gravity_W
    y = np.zeros((2, 13))
    y[:, 6] = 1.0
    y[0, 3:6] = [1.0 / 3.0, 2.0 / 7.0, 3.0 / 11.0]
    y[1, 0:3] = D * h * y[0, 3:6] + g * h ** 2 * D * (D + 1) / 2
    y[1, 3:6] = y[0, 3:6] + D * h * g
    inp = prepare_input(_traj_of([0.0, D * h], y), sc, "d.csv", dt_s=h)
    fl = exact_flow(sc, y[:1], inp.span_s)
    al = local_allowances(inp, y[:1], fl.M2, fl.rate, fl.roundoff)
    d = distances(y[1:], fl.y_end)
    assert d["position"][0] == pytest.approx(0.5 * 9.81 * h * D * h, rel=1e-9)
    assert d["position"][0] / al.total["position"][0] == pytest.approx(0.5 / tol.CHECK_LOCAL_C, rel=1e-6)


def test_error_growth_of_free_flight_is_the_elapsed_time():
    """δx(t) = δx0 + t δv0 and δv(t) = δv0 under gravity: G(v→x) = t (read at the growth grid's next
    point: at most one grid step, T/100, late), G(x→x) = G(v→v) = 1."""
    sc = load_scenario("projectile")
    t = np.linspace(0, 1, 11)
    g = error_growth(sc, t, {q: 1.0 for q in QUANTITIES})
    assert (np.all(g[("velocity", "position")] >= t * (1 - 1e-6))
            and np.all(g[("velocity", "position")] <= t + 0.01))
    np.testing.assert_allclose(g[("position", "position")], 1.0, rtol=1e-6)
    np.testing.assert_allclose(g[("velocity", "velocity")], 1.0, rtol=1e-6)
    assert np.all(g[("position", "velocity")] == 0.0)


def test_error_growth_of_an_isotropic_spin_is_the_elapsed_time():
    """A sphere spins at constant ω: an error δω turns the body by |δω| t more."""
    sc = scenario_from_parts(body="mass = 1.0\ninertia = [2.0, 2.0, 2.0]",
                             initial="angular_velocity = [0.0, 0.0, 3.0]", duration=2.0)
    t = np.linspace(0, 2, 9)
    g = error_growth(sc, t, {"position": 1.0, "velocity": 1.0, "orientation": 1.0, "angular_velocity": 3.0})
    G = g[("angular_velocity", "orientation")]
    assert np.all(G >= t * (1 - 1e-5)) and np.all(G <= t + 2.0 / 100)


def test_rk4_flow_takes_one_span_per_row():
    sc = load_scenario("tennis_racket")
    y0 = _random_rotation_states(5, seed=4)
    F = flow_rhs(sc)
    spans = np.array([0.001, 0.002, 0.004, 0.008, 0.016])
    batched = rk4_flow(F, y0, spans, 8)
    for k in range(5):
        np.testing.assert_allclose(batched[k], rk4_flow(F, y0[k:k + 1], spans[k], 8)[0], rtol=0, atol=1e-15)
    y_one = rk4_flow(F, y0[:1], 0.016, 8)
    np.testing.assert_allclose(np.linalg.norm(y_one[0, Q]), 1.0, atol=1e-15)   # unit stays unit


def test_a_sphere_turns_by_exp_of_its_spin_within_the_flows_own_error_estimate():
    from reference_sim.quaternion import quat_mul
    sc = scenario_from_parts(body="mass = 1.0\ninertia = [1.0, 1.0, 1.0]", duration=1.0)
    y0 = _random_rotation_states(3, seed=5)
    fl = exact_flow(sc, y0, np.full(3, 0.05))
    for k in range(3):
        ref = y0[k].copy()
        ref[Q] = quat_mul(quat_exp(0.05 * y0[k, W]), y0[k, Q])
        d = distances(fl.y_end[k:k + 1], ref[None], ("orientation",))["orientation"][0]
        assert d <= 10 * fl.error["orientation"][k] + 1e-15
        assert d <= 1e-3 * tol.CHECK_LOCAL_C * 0.05 ** 2 * fl.M2["orientation"][k]


def test_parse_scenario_helper_is_what_the_physics_tests_use():
    # guard: the isotropic-spin scenario above has no forces at all
    sc = parse_scenario('name = "s"\nduration = 1.0\ndt = 0.1\n[body]\nmass = 1.0\n'
                        'inertia = [1.0, 1.0, 1.0]\n[initial]\n')
    assert not sc.problem.forces.springs and np.all(sc.problem.forces.gravity_W == 0)


def test_a_spring_with_a_rest_length_turns_at_the_speed_across_it_over_its_length():
    # attachment at the COM, anchor at the origin: d = x. x = (0.5, 0, 0) m, v = (0, 2, 0) m/s:
    # |v⊥|/|d| = 4 /s; moving along d instead turns it not at all; a body spinning at 3 rad/s with the
    # attachment 0.1 m off its COM along x, at rest, moves the attachment at 0.3 m/s across d:
    # 0.3 / 0.6 = 0.5 /s
    spring = ("[[forces.spring]]\nanchor = [0.0, 0.0, 0.0]\nattach = [{a}, 0.0, 0.0]\nstiffness = 0.01\n"
              "rest_length = {L0}")
    sc = scenario_from_parts(initial="", forces=spring.format(a=0.0, L0=0.2))
    y = np.array([[0.5, 0, 0, 0, 2.0, 0, 1, 0, 0, 0, 0, 0, 0],
                  [0.5, 0, 0, 2.0, 0, 0, 1, 0, 0, 0, 0, 0, 0],
                  # d = 0: no direction, the spring exerts nothing
                  [0.0, 0, 0, 0, 2.0, 0, 1, 0, 0, 0, 0, 0, 0]])
    assert spring_turn_rate(sc.problem, y) == pytest.approx([4.0, 0.0, 0.0], abs=1e-15)
    assert motion_rate(sc, y)[0] == pytest.approx(4.0)   # above √(k/m) = 0.1 /s and |ω| = 0
    off = scenario_from_parts(initial="", forces=spring.format(a=0.1, L0=0.2))
    spin = np.array([[0.5, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 3.0]])
    assert spring_turn_rate(off.problem, spin)[0] == pytest.approx(0.3 / 0.6)
    zero_length = scenario_from_parts(initial="", forces=spring.format(a=0.0, L0=0.0))   # −k d: linear in d
    assert spring_turn_rate(zero_length.problem, y)[0] == 0.0


def test_the_lever_arms_rounding_in_omega_is_allowed_and_nothing_more():
    """A body that never turns, stepped by a correct scheme, whose ω carries what an engine's lever arm
    leaves (r = two points near x_W, each rounded: u |x| |F| of torque): within its one-step allowance; the
    same noise 100× larger (than the allowance) is a defect, so the allowance is that rounding and not a
    blanket. The scale is hand-derived: ω moves by Δt u |x| |F| / I_min a step."""
    from cross_checks.analysis.flow import lever_arm_roundoff, run_local_defect
    from cross_checks.engines import run_variant
    sc = load_scenario("linear_drag")                  # thrown, never turns: ω = 0 exactly
    dt = sc.dt_s
    y = run_variant(sc, "reference:course", dt).y
    assert np.all(y[:, 10:13] == 0.0)
    u = 2.0 ** -53
    step = lever_arm_roundoff(sc, y[:-1], u, dt)
    m, a = sc.problem.body.mass_kg, np.linalg.norm(y[1, 3:6] - y[0, 3:6]) / dt   # |F| = m |Δv/Δt| here
    i_min = np.min(np.linalg.eigvalsh(sc.problem.body.inertia_B))
    assert step[1] == pytest.approx(dt * u * np.linalg.norm(y[1, 0:3]) * m * a / i_min, rel=0.05)
    rng = np.random.default_rng(3)
    for scale, within in ((1.0, True), (100.0 * tol.CHECK_ROUNDINGS_PER_STEP, False)):
        noisy = y.copy()
        kicks = scale * step[:, None] * rng.choice([-1.0, 1.0], size=(len(step), 3))
        noisy[1:, 10:13] = np.cumsum(kicks, axis=0)   # a random walk of per-step kicks, as an engine leaves
        ratio, quantity, _ = run_local_defect(sc, noisy, dt, unit_roundoff=u)
        assert (ratio <= 1.0) == within, (scale, ratio, quantity)
        if not within:
            assert quantity == "angular_velocity"

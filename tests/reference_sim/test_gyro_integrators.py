"""The gyroscopic schemes of engines (Bullet, Jolt) and of the rigid-body literature (Buss, DLM, the implicit
midpoint rule, Moser–Veselov): one step against an independent derivation, what each keeps by construction,
and the global order without forces (the closed form) and with every force kind (DOP853)."""
import numpy as np
import pytest

from reference_sim.analytic import torque_free
from reference_sim.body import RigidBody
from reference_sim.forces import ForceModel
from reference_sim.ground_truth import ground_truth
from reference_sim.integrators import BULLET_MAX_GYROSCOPIC_TORQUE, VARIANTS, get_step
from reference_sim.quaternion import geodesic_angle, matrix_from_quat, quat_conj, quat_mul, quat_normalize
from reference_sim.simulate import run_members, simulate
from reference_sim.state import Problem, State
from tests.helpers.oracle import step_readable
from tests.helpers.tolerances import GYRO_ONE_STEP, KEPT_TO_ROUNDOFF, ORDER_TOL, SAME_STEP_TWO_AXES

from .test_integrators import _orders, coupled_problem

FIRST = ["implicit_gyro_body", "implicit_gyro_world", "explicit_gyro_clamped", "jolt_gyro"]
SECOND = ["buss_augmented", "dlm_splitting", "lp_midpoint", "moser_veselov"]
NEW = FIRST + SECOND


def tumbling(w_B=(0.6, 1.5, 0.4), moments=(1.0, 2.0, 3.0)):
    """A torque-free body with products of inertia (its principal axes turned), tumbling far from the
    separatrix, at a general attitude."""
    P = matrix_from_quat(quat_normalize([1.0, 0.3, -0.2, 0.1]))
    I_B = P @ np.diag(moments) @ P.T
    q0 = quat_normalize([0.9, 0.1, 0.3, -0.2])
    w_W = matrix_from_quat(q0) @ (P @ np.asarray(w_B, float))
    return Problem(RigidBody(1.0, I_B), ForceModel(), State(np.zeros(3), np.zeros(3), q0, w_W))


def momentum_energy(problem, y):
    """World angular momentum L (..., 3) and rotational energy E (...) of states y (..., 13)."""
    R = matrix_from_quat(y[..., 6:10])
    L = np.einsum("...ij,...j->...i", R @ problem.body.inertia_B @ np.swapaxes(R, -1, -2), y[..., 10:13])
    return L, 0.5 * np.einsum("...i,...i->...", L, y[..., 10:13])


@pytest.mark.parametrize("variant", NEW)
@pytest.mark.parametrize("dt", [1e-2, 5e-2])
def test_one_step_is_its_sources_step(variant, dt):
    # the definition against the scheme transcribed from its source (tests/helpers/oracle.py): torque-free
    # here; with every force kind and decay over 200 steps: tests/reference_sim/test_readable.py
    problem = tumbling()
    y0 = problem.initial_packed()
    y1 = get_step(variant)(problem, y0, dt)
    np.testing.assert_allclose(y1, step_readable(variant, problem, y0, dt), rtol=0, atol=GYRO_ONE_STEP)


@pytest.mark.parametrize("variant", NEW)
def test_members_advance_on_their_own(variant):
    # a member's run is the same alone and in a batch of other problems and steps (row by row solves)
    problems = [tumbling(), coupled_problem((0.99, 0.995)), tumbling((0.1, 3.0, 0.1))]
    from reference_sim.forces import Members
    runs = run_members(Members.stack(problems), variant, [1e-2, 2e-3, 5e-3], [40, 60, 50],
                       np.array([p.initial_packed() for p in problems]))
    for p, dt, n, run in zip(problems, (1e-2, 2e-3, 5e-3), (40, 60, 50), runs):
        assert np.array_equal(run.y, simulate(p, variant, dt, n).y)


def test_bullets_body_and_world_implicit_steps_are_the_same_step():
    # [Rω]× = R[ω]×Rᵀ and I_W = R I_B Rᵀ held: the world-axes Newton step is the body-axes one rotated
    problem = tumbling()
    a = simulate(problem, "implicit_gyro_body", 5e-3, 2000).y
    b = simulate(problem, "implicit_gyro_world", 5e-3, 2000).y
    assert np.max(np.abs(a - b)) < SAME_STEP_TWO_AXES


@pytest.mark.parametrize("variant", ["implicit_gyro_body", "implicit_gyro_world"])
def test_the_implicit_gyroscopic_step_damps_energy_and_momentum(variant):
    problem = tumbling()
    y = simulate(problem, variant, 1e-2, 1000).y
    L, E = momentum_energy(problem, y)
    assert np.all(np.diff(E) < 0.0) and np.all(np.diff(np.linalg.norm(L, axis=-1)) < 0.0)
    assert E[-1] < 0.99 * E[0]


def test_the_explicit_gyroscopic_torque_is_clamped_to_bullets_maximum():
    problem = tumbling()
    y0 = problem.initial_packed()
    # below the clamp (|ω × I ω| ≈ 1.5 N m) it is expmap_gyro, to round-off
    np.testing.assert_allclose(get_step("explicit_gyro_clamped")(problem, y0, 1e-2),
                               get_step("expmap_gyro")(problem, y0, 1e-2), rtol=0, atol=1e-15)
    # above it the gyroscopic torque is cut to BULLET_MAX_GYROSCOPIC_TORQUE along its direction
    fast = y0.copy()
    fast[10:13] *= 40.0
    R = matrix_from_quat(fast[6:10])
    I_W = R @ problem.body.inertia_B @ R.T
    g = np.cross(fast[10:13], I_W @ fast[10:13])
    assert np.linalg.norm(g) > 10 * BULLET_MAX_GYROSCOPIC_TORQUE
    w1 = get_step("explicit_gyro_clamped")(problem, fast, 1e-3)[10:13]
    expected = fast[10:13] - 1e-3 * np.linalg.solve(I_W, BULLET_MAX_GYROSCOPIC_TORQUE * g / np.linalg.norm(g))
    np.testing.assert_allclose(w1, expected, rtol=1e-14, atol=1e-12)


def test_jolt_keeps_the_momentum_magnitude_and_its_energy_drifts_to_the_intermediate_axis():
    # |L| exact: the explicit momentum step is rescaled to its old length. The energy then moves towards
    # L²/2I₂ (its explicit step gains ½Δt² (ω×L)·I⁻¹(ω×L), the rescaling takes back E|ω×L|²Δt²/|L|²):
    # up from a spin about the major axis, down from one about the minor axis.
    for axis, sign in ((2, +1), (0, -1)):
        w_B = np.full(3, 0.05)
        w_B[axis] = 2.0
        problem = tumbling(w_B)
        y = simulate(problem, "jolt_gyro", 1e-2, 5000).y
        L, E = momentum_energy(problem, y)
        l2 = np.sum(L * L, axis=-1)
        assert np.max(np.abs(np.sqrt(l2) / np.sqrt(l2[0]) - 1.0)) < KEPT_TO_ROUNDOFF
        delta = 2.0 * E * 2.0 / l2 - 1.0          # separatrix distance (2E I₂ − L²)/L², I₂ = 2
        assert sign * (delta[-1] - delta[0]) > 0.0 and abs(delta[-1]) < abs(delta[0]), (axis, delta[[0, -1]])


@pytest.mark.parametrize("variant", ["lp_midpoint", "moser_veselov"])
def test_midpoint_and_moser_veselov_keep_energy_and_momentum_to_roundoff(variant):
    problem = tumbling((0.1, 2.0, 0.1))            # near the separatrix: the flips test the solve hardest
    y = simulate(problem, variant, 2e-2, 2000).y
    L, E = momentum_energy(problem, y)
    assert np.max(np.abs(E / E[0] - 1.0)) < KEPT_TO_ROUNDOFF
    assert np.max(np.linalg.norm(L - L[0], axis=-1)) < KEPT_TO_ROUNDOFF * np.linalg.norm(L[0])


@pytest.mark.parametrize("variant", ["dlm_splitting", "buss_augmented"])
def test_the_world_momentum_is_kept_exactly_by_the_maps_that_hold_it(variant):
    problem = tumbling((0.1, 2.0, 0.1))
    y = simulate(problem, variant, 2e-2, 2000).y
    L, _ = momentum_energy(problem, y)
    assert np.max(np.linalg.norm(L - L[0], axis=-1)) < KEPT_TO_ROUNDOFF * np.linalg.norm(L[0])


def test_dlm_is_symplectic_its_energy_error_stays_bounded():
    # no secular drift: over 4000 steps (~25 periods of the polhode) the error of the last fifth is no larger
    # than that of the first fifth, and it is O(Δt²)
    problem = tumbling()
    for dt in (4e-2, 2e-2):
        _, E = momentum_energy(problem, simulate(problem, "dlm_splitting", dt, 4000).y)
        err = np.abs(E / E[0] - 1.0)
        first, last = np.max(err[:800]), np.max(err[-800:])
        assert last < 1.2 * first and first < (dt / 2e-2) ** 2 * 1e-3, (dt, first, last)


def test_moser_veselov_is_the_midpoint_step_of_a_rescaled_step():
    # Δt Π = 2/(1+|f|²)(I f + f × I f) is the midpoint equation Δt′ Π = 2 (I f + f × I f) of Δt′ = Δt (1+|f|²)
    problem, h = tumbling(), 0.05
    y0 = problem.initial_packed()
    y_mv = get_step("moser_veselov")(problem, y0, h)
    rel = quat_mul(quat_conj(y0[6:10]), y_mv[6:10])      # q₀⁻¹ q₁ = [1, f]/|·|: f in body axes
    f = rel[1:] / rel[0]
    y_mid = get_step("lp_midpoint")(problem, y0, h * (1.0 + f @ f))
    np.testing.assert_allclose(y_mid, y_mv, rtol=0, atol=GYRO_ONE_STEP)


def test_on_a_principal_axis_spin_the_cayley_maps_turn_by_their_own_angle():
    # exp-map attitudes (Buss, DLM) turn by |ω|Δt; the midpoint rule by 2 atan(|ω|Δt/2); Moser–Veselov by
    # asin(|ω|Δt)
    w, h = 2.0, 0.05
    problem = Problem(RigidBody(1.0, [1.0, 2.0, 3.0]), ForceModel(),
                      State(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), np.array([0.0, 0.0, w])))
    for variant, angle in (("buss_augmented", w * h), ("dlm_splitting", w * h),
                           ("lp_midpoint", 2 * np.arctan(w * h / 2)), ("moser_veselov", np.arcsin(w * h))):
        y1 = get_step(variant)(problem, problem.initial_packed(), h)
        assert abs(2 * np.arctan2(y1[9], y1[6]) - angle) < GYRO_ONE_STEP, variant
        assert np.max(np.abs(y1[10:13] - [0.0, 0.0, w])) <= 1e-15, variant   # ω kept: one rounding


LADDER = {1: [8e-3, 4e-3, 2e-3, 1e-3], 2: [2e-2, 1e-2, 5e-3, 2.5e-3]}


@pytest.mark.parametrize("variant", NEW)
def test_global_order_on_a_torque_free_tumble(variant):
    # against the closed form (Jacobi's elliptic functions, reference_sim.analytic)
    problem, T = tumbling(), 2.0
    q_ex, w_ex = (a[-1] for a in torque_free(problem.body.inertia_B, problem.initial.q_WB,
                                               problem.initial.w_W, np.array([0.0, T])))
    p = VARIANTS[variant].order
    errs_q, errs_w = [], []
    for dt in LADDER[p]:
        y = simulate(problem, variant, dt, int(round(T / dt))).y[-1]
        errs_q.append(float(geodesic_angle(q_ex, y[6:10])))
        errs_w.append(np.linalg.norm(y[10:13] - w_ex))
    for errs in (errs_q, errs_w):
        assert abs(_orders(errs, LADDER[p]) - p) < ORDER_TOL, errs


@pytest.mark.parametrize("variant", NEW)
def test_global_order_with_every_force_kind_and_decay(variant):
    # springs off the COM, drag, point forces, torques in both frames, velocity decay (DOP853 ground truth)
    problem, T = coupled_problem((0.99, 0.995)), 1.0
    truth = ground_truth(problem, np.array([0.0, T]))[-1]
    p = VARIANTS[variant].order
    dts = LADDER[p]
    errs = {k: [] for k in ("x", "v", "q", "w")}
    for dt in dts:
        y = simulate(problem, variant, dt, int(round(T / dt))).y[-1]
        errs["x"].append(np.linalg.norm(y[0:3] - truth[0:3]))
        errs["v"].append(np.linalg.norm(y[3:6] - truth[3:6]))
        errs["q"].append(float(geodesic_angle(truth[6:10], y[6:10])))
        errs["w"].append(np.linalg.norm(y[10:13] - truth[10:13]))
    for k, e in errs.items():
        assert abs(_orders(e, dts) - p) < ORDER_TOL, (k, e)


@pytest.mark.parametrize("variant", NEW)
def test_a_blown_up_row_spoils_no_other_row_and_raises_nothing(variant):
    # rbcheck check steps every recorded row of a file at once, blown-up rows included: a singular matrix or
    # a non-finite Newton iterate gives that row a non-finite state, never an exception
    problem = tumbling()
    good = problem.initial_packed()
    for bad_w in (np.inf, np.nan, 1e200):
        bad = good.copy()
        bad[10:13] = bad_w
        with np.errstate(all="ignore"):
            out = get_step(variant)(problem, np.array([good, bad, good]), 1e-2)
        assert np.array_equal(out[0], get_step(variant)(problem, good, 1e-2))
        assert np.array_equal(out[0], out[2])
        if variant == "jolt_gyro":   # |L′|² is inf or NaN for each of these
            # Jolt's own test `|L′|² > 0 ? … : 0` sends a non-finite momentum to zero: transcribed, not fixed
            assert np.array_equal(out[1][10:13], np.zeros(3))
        else:
            assert not np.all(np.isfinite(out[1])) or np.max(np.abs(out[1])) > 1e8, (bad_w, out[1])

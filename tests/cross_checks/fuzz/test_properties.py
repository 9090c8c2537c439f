"""The fuzz's verdict rules, each against numbers rbcheck did not compute (hand-derived or an engine's)."""
import numpy as np
import pytest

from cross_checks.analysis.judge import two_term_consistent
from cross_checks.engines import resolve
from tests.helpers.scenarios import RK4_PRE_ASYMPTOTIC_FROM_BELOW

H = np.array([0.0377, 0.01885, 0.009425])


def test_an_order_p_error_with_a_large_next_term_is_two_term_consistent():
    # measured by the fuzz on reference:course (a weakly decayed spring from rest, 8 steps): e/h is affine
    assert two_term_consistent(H, [1.26e-4, 1.52e-4, 9.79e-5], [1e-13] * 3, 1.0)
    # hand-built: a h + b h² with b h = −0.74 a at the coarsest rung
    a, b = 0.0128, -0.25
    assert two_term_consistent(H, a * H + b * H ** 2, [0.0] * 3, 1.0)
    assert two_term_consistent(H, 3.0 * H ** 4 - 50.0 * H ** 5, [0.0] * 3, 4.0)


@pytest.mark.parametrize("order, errors", [
    (1.0, 0.3 + 0 * H),          # a plateau (decay twice, a frame mix-up)
    (1.0, 0.3 * H ** 0.5),       # half an order short
    (4.0, 2.0 * H ** 2),         # RK4 with a wrong stage weight: order 2
    (2.0, 5.0 * H),              # mid-point stage at the full step: order 1
])
def test_a_wrong_order_is_not_two_term_consistent(order, errors):
    assert not two_term_consistent(H, errors, [0.0] * 3, order)


def test_floors_small_beside_the_errors_leave_a_wrong_order_wrong():
    # each error allowed 2 % of round-off: a wrong order stays far from a two-term fit
    for order, e in [(4.0, 2.0 * H ** 2), (2.0, 5.0 * H), (1.0, 0.3 * H ** 0.5), (1.0, 0.3 + 0 * H)]:
        assert not two_term_consistent(H, e, e / 50.0, order)
    # and an order-p error with a large next term stays consistent, its floors or not
    a, b = 0.0128, -0.25
    e = a * H + b * H ** 2
    assert two_term_consistent(H, e, e / 50.0, 1.0)


def test_an_order_3_rk4_with_three_resolved_rungs_is_not_excused():
    # a pure third-order error where a fourth is expected: u = e/h⁴ ∝ 1, 2, 4 → third difference 1 − 6 + 8 = 3
    # of max 4 (0.75 > 0.25), with floors a thousand times below the finest error
    e = 1.35e-12 * (H / H[0]) ** 3
    assert not two_term_consistent(H, e, [e[-1] / 1000.0] * 3, 4.0)


def test_a_finest_rung_within_its_floor_leaves_the_order_undecided():
    """The fuzz's reference:rk4 at seed 2026 case 10975 (a short torque-free spin, 8–32 steps): angular
    velocity errors measured 1.35e-12, 1.25e-13, 1.08e-14 rad/s over floors 0.91, 1.22, 1.64e-14. The same
    scheme in 80-bit extended precision (no round-off at this level), against itself at h/256, has truncation
    errors 1.3528e-12, 1.2495e-13, 1.0318e-14, 7.32e-16, 4.86e-17: pairwise orders 3.44, 3.60, 3.82, 3.91 —
    order 4 approached from below (the next term cancels part of the leading one), not order 3.44."""
    dts = [0.0012141872302859603, 0.0006070936151429801, 0.00030354680757149006]
    assert two_term_consistent(dts, [1.3526506e-12, 1.2498094e-13, 1.0807438e-14],
                               [9.147727e-15, 1.2150679e-14, 1.6397493e-14], 4.0)
    # the extended-precision errors themselves are consistent as measured
    assert two_term_consistent(dts, [1.3528e-12, 1.2495e-13, 1.0318e-14], [0.0] * 3, 4.0)
    # on two resolved rungs a third order cannot be told from it either: no claim either way
    e3 = 1.3526506e-12 * (np.array(dts) / dts[0]) ** 3     # 1.35e-12, 1.69e-13, 2.11e-14
    assert two_term_consistent(dts, e3, [9.147727e-15, 1.2150679e-14, 1.6397493e-14], 4.0)


def test_the_lever_arm_floor_covers_mujocos_measured_round_off():
    """A tensor body at rest falling far from the origin: the true ω stays exactly 0, MuJoCo's picks up
    round-off from lever arms measured from the world origin — above the plain ε floor, below the
    lever-arm term of analysis.metrics.lever_roundoff."""
    from cross_checks.analysis.metrics import lever_arms, lever_roundoff
    from cross_checks.engines import get_adapter
    from cross_checks.fuzz.pipeline import scenario_of
    I = np.diag([0.00113, 0.0128, 0.0131])
    R = np.linalg.qr(np.array([[1.0, 0.3, 0.2], [0.1, 1.0, 0.4], [0.3, 0.2, 1.0]]))[0]
    spec = {"name": "lever", "duration": 0.4, "dt": 0.01,
            "body": {"mass": 9.25, "inertia": (R @ I @ R.T).tolist()},
            "initial": {"position": [0.4, -0.3, 0.5], "velocity": [0.28, 0.0, 0.0]},
            "forces": {"gravity": [0.0, 0.0, -11.65]}}
    sc = scenario_of(spec)
    run = get_adapter("mujoco").simulate(sc, "euler", 0.01, 40)
    w_err = float(np.max(np.linalg.norm(np.asarray(run.y)[:, 10:13], axis=1)))
    y_ref = np.asarray(get_adapter("reference").simulate(sc, "rk4", 0.01, 40).y)
    lv = lever_roundoff(lever_arms(sc.problem, y_ref), 2.0 ** -52)
    assert w_err > 10 * 2.0 ** -52           # above any ε |ω| (|ω| = 0 here): it is the lever arms
    assert w_err <= lv["acc_rad_s2"] * sc.duration_s


def test_a_too_low_order_that_the_measured_round_off_leaves_room_for_is_no_claim():
    # the fuzz (seed 3, case 190) called drake:runge_kutta3 order 2.66: its lever-arm floor dropped the finest
    # rung, leaving the coarsest pair, bent by the next term; within the floors the order can be 2.89
    from cross_checks.analysis.expectations import Expectation
    from cross_checks.fuzz.properties import _fit_record
    exp = Expectation("converges", 3.0, "an order-3 scheme")
    dts = [0.024343227673126657, 0.012171613836563329, 0.006085806918281664]
    e = [8.619677552088268e-11, 1.3597802417763613e-11, 1.8910664527449406e-12]
    fl = [1.762448012359544e-13, 2.307381268013016e-13, 3.078033268746281e-13]
    assert _fit_record(None, "drake:runge_kutta3", "orientation", dts, e, fl, None, exp,
                       "free_running_order") == (None, False)
    # the same ladder with an order-2 scheme's finest error (resolved 11x above its floor): still a violation
    e_wrong = e[:2] + [e[1] / 4.0]
    rec, claimed = _fit_record(None, "drake:runge_kutta3", "orientation", dts, e_wrong, fl, None, exp,
                               "free_running_order")
    assert claimed and rec is not None and rec["order"] < 2.7


def test_case_10975_is_order_4_approached_from_below_in_extended_precision(tmp_path):
    """The numbers of test_a_finest_rung_within_its_floor_leaves_the_order_undecided, measured: the
    reference's RK4 stepped in 80-bit long double (round-off ~1e-19 relative, far below these errors), its
    angular velocity against the same scheme at h/256 (error ~(1/256)⁴ of the coarsest, 3e-22 rad/s)."""
    from cross_checks.scenario.parse import load_scenario
    from reference_sim.integrators import get_step
    if np.finfo(np.longdouble).eps > 1e-18:
        pytest.skip("no extended precision on this platform")
    path = tmp_path / "case.toml"
    path.write_text(RK4_PRE_ASYMPTOTIC_FROM_BELOW)
    sc = load_scenario(path)
    T, n0 = np.longdouble(sc.duration_s), round(sc.duration_s / sc.dt_ladder_s[0])

    def omega_rows(n):
        step, h = get_step("rk4"), T / n   # the definition keeps the precision of its states and step
        y = sc.problem.initial_packed().astype(np.longdouble)[None]
        rows = [y[0, 10:13]]
        for _ in range(n):
            y = step(sc.problem, y, h)
            rows.append(y[0, 10:13])
        return np.array(rows)

    fine = omega_rows(n0 * 256)
    errs = [float(np.max(np.linalg.norm((omega_rows(n0 * k) - fine[::256 // k]).astype(float), axis=1)))
            for k in (1, 2, 4, 8)]
    pairs = [np.log2(a / b) for a, b in zip(errs, errs[1:])]
    assert 3.3 < pairs[0] < pairs[1] < pairs[2] < 4.0, pairs          # rising towards 4, from 3.44
    assert abs(errs[0] - 1.3526506e-12) < 0.01 * errs[0]              # the float64 run's error at h


def test_the_fuzz_does_not_hold_a_clamped_step_to_the_physical_conservation_where_the_clamp_acts():
    # rbcheck fuzz (seed 0, batch 0) drew a fast spin of a large body: Bullet's clamped gyroscopic torque
    # solves another equation there, whose momentum drift is not a consistent scheme's
    from cross_checks.analysis.physics import scenario_physics
    from cross_checks.fuzz.properties import _models_physics
    from cross_checks.scenario import parse_scenario
    from tests.cross_checks.analysis.test_expectations import CLAMPED
    sc = parse_scenario(CLAMPED)
    phys = scenario_physics(sc)
    assert not _models_physics(sc, resolve("reference:explicit_gyro_clamped"), phys)
    assert _models_physics(sc, resolve("reference:expmap_gyro"), phys)

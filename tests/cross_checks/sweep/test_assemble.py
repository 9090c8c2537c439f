"""The sweep's convergence floors and same-scheme agreement (cross_checks.sweep.assemble) take the one rule
the fuzz takes too (analysis.metrics.run_floor, same_scheme_allowance)."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from cross_checks.analysis import metrics as M
from cross_checks.core import tolerances as tol
from cross_checks.engines import resolve
from cross_checks.fuzz import properties as P
from cross_checks.scenario import load_scenario
from cross_checks.sweep import assemble

LEVER = {"position_max_m": 9.0, "velocity_max_m_s": 3.0, "angular_velocity_max_rad_s": 12.0,
         "force_max_N": 5.0, "mass_kg": 0.3, "inertia_min_kg_m2": 1.2e-4}
SCALES = {"position": 9.0, "velocity": 3.0, "orientation": math.pi, "angular_velocity": 12.0}
REF_ERR = {"position": 1e-13, "velocity": 2e-13, "orientation": 3e-13, "angular_velocity": 4e-13}
AMP = {"position": 2.0, "velocity": 3.0, "orientation": 4.0, "angular_velocity": 5.0}


@pytest.mark.parametrize("variant", ["mujoco:euler", "reference:expmap_gyro"])
@pytest.mark.parametrize("q", ["position", "velocity", "orientation", "angular_velocity"])
def test_the_sweep_and_the_fuzz_give_a_ladder_the_same_floors(variant, q):
    variant = resolve(variant)
    ladder = [{"dt": 0.01 / 2 ** k, "steps": 100 * 2 ** k} for k in range(3)]
    measured = {"reference_error": REF_ERR, "amplification": AMP, "lever_arms": LEVER,
                "local_reference_error": {repr(r["dt"]): REF_ERR for r in ladder}}
    ctx = SimpleNamespace(scales=SCALES, lever=LEVER)
    sweep = assemble.ladder_floors(ladder, q, SCALES, "free_running", "analytic", measured, variant)
    fuzz = [P.case_floor(ctx, variant, q, r["steps"], r["dt"], REF_ERR[q], AMP[q]) for r in ladder]
    assert sweep == fuzz
    one = assemble.ladder_floors(ladder, q, SCALES, "one_step", "analytic", measured, variant)
    assert one == [P.case_floor(ctx, variant, q, 1, r["dt"], REF_ERR[q]) for r in ladder]
    # an engine's floors hold its lever arms where measured (the fuzz's), rbcheck's own schemes' do not
    without = assemble.ladder_floors(ladder, q, SCALES, "free_running", "analytic",
                                     {**measured, "lever_arms": None}, variant)
    assert (sweep > without if variant.startswith("mujoco") else sweep == without)
    unmeasured = SimpleNamespace(scales=SCALES, lever=None)
    assert without == [P.case_floor(unmeasured, variant, q, r["steps"], r["dt"], REF_ERR[q], AMP[q])
                       for r in ladder]


def _rec(y, status="ok"):
    return {"row": {"status": status, "diverged_at_s": None}, "y_final": y}


def test_the_sweep_s_agreement_allows_the_amplified_round_off_the_fuzz_allows():
    sc = load_scenario("tennis_racket")
    n = sc.n_steps()
    amp = 400.0
    ref = SimpleNamespace(error="", scales={"position": 1.0, "velocity": 1.0, "orientation": math.pi,
                                             "angular_velocity": 5.0},
                          measured={"amplification": {"position": 1.0, "velocity": 1.0, "orientation": amp,
                                                      "angular_velocity": 7.0}})
    allowed = M.same_scheme_allowance(n, tol.ROUNDOFF_PER_STEP_REL, amp)
    assert allowed > tol.SAME_SCHEME_REL     # the tennis racket's amplification: more than the fixed floor
    y = np.zeros(13)
    y[6], y[10] = 1.0, 5.0
    for factor, agrees in ((0.5, True), (2.0, False)):
        yb = y.copy()
        yb[10] += factor * allowed * 5.0       # an angular velocity difference of factor × the allowance
        rec = assemble._agreement(resolve("reference:expmap_gyro"), resolve("mujoco:euler"), "same", sc,
                                  _rec(y), _rec(yb), ref)
        assert rec["agrees"] is agrees and rec["tolerance"] == allowed
        assert rec["max_rel"] == pytest.approx(factor * allowed, rel=1e-6)

"""cross_checks.sweep.repro_measure: what a reproducer measures, on a world made here (no engine)."""
import contextlib
import io

import numpy as np

from cross_checks.sweep import repro_measure as rm


class _Drifting:
    """A world of one body that moves along x at 1 m/s and, from step ``blow`` on, holds NaN (a blow-up as
    an engine that goes on after one gives it)."""

    def __init__(self, bodies, gravity_W, variant, dt_s, blow=None):
        self.dt_s, self.blow, self.k = dt_s, blow, 0

    def set_state(self, y):
        self.y = np.array(y, dtype=float)

    def apply(self, f_W, tau_W):
        pass

    def step(self):
        self.k += 1
        self.y[0, 0] += self.dt_s
        if self.blow is not None and self.k >= self.blow:
            self.y[0, :] = np.nan

    def read(self):
        return self.y.copy()

    def packed(self, raw):
        return raw


def _globals(dts, steps):
    y0 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    return {"DIST": [], "BODIES": [(1.0, np.eye(3), None)], "GRAVITY_W": [0.0, 0.0, 0.0], "VARIANT": "fake",
            "Y0": y0, "F_W": [0.0] * 3, "TAU_W": [0.0] * 3, "QUANTITY": "position", "DT_S": dts,
            "STEPS": steps, "Y_REF": [[n * h] + y0[1:] for h, n in zip(dts, steps)],
            "FLOORS": [1e-15] * len(dts), "DECLARED": 1.0, "ORDER_TOL": 0.3, "RESOLVED": 10.0}


def test_diverged_at_is_the_first_non_finite_or_huge_state():
    y = np.zeros((5, 13))
    assert rm.diverged_at(y, 0.1) is None
    y[3, 2] = 2e8
    assert rm.diverged_at(y, 0.1) == 0.1 * 3
    y[2, 5] = np.inf
    assert rm.diverged_at(y, 0.1) == 0.1 * 2


def test_an_order_claim_whose_runs_blow_up_is_a_defect_not_an_exact_run():
    # every run ends in NaN: no error is finite, so no point is resolved; the fit alone would call the run
    # exact ("at round-off") and exit 0, while the engine blew up (Newton's Featherstone far from the origin)
    s = _globals([0.02, 0.01], [50, 100])
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = rm.main_order(lambda *a: _Drifting(*a, blow=30), s)
    assert code == 1
    lines = out.getvalue().splitlines()
    assert lines[1] == "dt = 0.02 s: the state diverged at t = 0.6 s"
    assert lines[-1].endswith("the run diverged at 2 of 2 Δt, expected order 1: DEFECT")


def test_an_order_claim_on_runs_that_do_not_blow_up_is_fitted():
    s = _globals([0.02, 0.01], [50, 100])   # the world's x is exact: the errors are round-off
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = rm.main_order(_Drifting, s)
    assert code == 0 and "error" in out.getvalue().splitlines()[1]

"""cross_checks.sweep.repro_measure: what a reproducer measures, on planted worlds whose answer is known.
The invariance claim's judgement: within the allowance it holds; beyond it, a deviation that vanishes at the
step's order as Δt shrinks is the step's own (step-dependent, exit 0), one that does not is broken (exit 1),
as the sweep's refinement (sweep.invariance) decides. An order claim whose runs blow up is a defect."""
import contextlib
import io

import numpy as np
import pytest

from cross_checks.sweep import repro_measure as rm

QUANTITIES = ("position", "orientation", "velocity", "angular_velocity")


def _planted(kind):
    """A world of one body at rest, stepped exactly (nothing moves), except the transformed one (mass 2 kg),
    whose position gains: ``dt²`` a step ("truncation": after T/dt steps T·dt, first order), a fixed 1e-3 m at
    its first step ("plateau": a wrong model), 1e-10 m ("rounding": within the allowance, beyond the base
    round-off), nothing ("exact")."""
    class World:
        def __init__(self, bodies, gravity_W, variant, dt_s):
            self.moved = bodies[0][0] == 2.0
            self.dt, self.n, self.y = dt_s, 0, None

        def set_state(self, y):
            self.y = np.array(y, dtype=float)

        def apply(self, f_W, tau_W):
            pass

        def step(self):
            if self.moved and kind == "truncation":
                self.y[0, 0] += self.dt ** 2
            elif self.moved and kind in ("plateau", "rounding") and self.n == 0:
                self.y[0, 0] += 1e-3 if kind == "plateau" else 1e-10
            self.n += 1

        def read(self):
            return self.y.copy()

        def packed(self, raw):
            return raw
    return World


def _numbers(step_order=0.7):
    one = [1.0, 0.0, 0.0, 0.0]
    y0 = [0.0] * 6 + one + [0.0] * 3
    dts = [0.01, 0.005, 0.0025]
    allow = {q: 1e-9 for q in QUANTITIES}
    return {"DIST": (), "VARIANT": "euler", "SCENARIO": "planted", "TRANSFORM": "rotation 135 deg",
            "BODIES": [(1.0, [1.0, 2.0, 3.0], one)], "BODIES_T": [(2.0, [1.0, 2.0, 3.0], one)],
            "GRAVITY_W": [0.0] * 3, "GRAVITY_T": [0.0] * 3, "Y0": y0, "Y0_T": y0, "F_W": [0.0] * 3,
            "TAU_W": [0.0] * 3, "F_T": [0.0] * 3, "TAU_T": [0.0] * 3, "MAP_D": [0.0] * 3,
            "MAP_R": np.eye(3).tolist(), "MAP_R_INV": one, "MAP_P_INV": one, "MAP_K": 1.0,
            "DT_S": dts, "STEPS": [int(round(1.0 / h)) for h in dts], "BASE": {q: 1e-12 for q in QUANTITIES},
            "ALLOWANCE": [dict(allow) for _ in dts], "STEP_ORDER": {q: step_order for q in QUANTITIES},
            "UNITS": {q: "u" for q in QUANTITIES}}


@pytest.mark.parametrize("kind,step_order,code,verdict", [
    ("exact", 0.7, 0, "holds"),
    ("rounding", 0.7, 0, "precision loss (expected)"),   # beyond the base 1e-12, within the allowance 1e-9
    ("truncation", 0.7, 0, "step-dependent"),   # 0.01, 0.005, 0.0025 m: order 1.00 each halving
    ("truncation", 1.7, 1, "broken"),           # ... but the variant's step is order 2: a lower order
    ("plateau", 0.7, 1, "broken"),              # 1e-3 m at every Δt: order 0
])
def test_the_invariance_verdict_refines_as_the_sweep_does(kind, step_order, code, verdict, monkeypatch):
    monkeypatch.setattr(rm, "versions", lambda dists: None)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        got = rm.main_invariance(_planted(kind), _numbers(step_order))
    last = out.getvalue().strip().splitlines()[-1]
    assert got == code and f"under rotation 135 deg: {verdict}" in last, out.getvalue()
    if kind == "truncation":
        assert "position largest deviation 0.01, 0.005, 0.0025 u" in out.getvalue()
        assert "order 1.00, 1.00" in out.getvalue()


def test_map_back_undoes_each_transform_as_transforms_py_does():
    """The script's one map back, with the numbers a transform sets, equals Transform.map_back."""
    from cross_checks.scenario.transforms import default_transforms
    from cross_checks.sweep.repro import map_numbers
    rng = np.random.default_rng(7)
    y = rng.normal(size=(5, 13))
    y[:, 6:10] /= np.linalg.norm(y[:, 6:10], axis=-1, keepdims=True)
    for t in default_transforms():
        got = rm.map_back(y, map_numbers(t))
        np.testing.assert_allclose(got, t.map_back(y), rtol=0, atol=1e-15, err_msg=t.label)


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

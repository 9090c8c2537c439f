"""In float32 the rotation's round-off adds up linearly too (analysis.metrics.roundoff_floor: b·N for every
quantity when ε is float32's; position and velocity only in float64, unchanged). Measured on PhysX 5.3.1's PGS
step (docs/engine_conventions.md, "PhysX 5.3.1 (SAPIEN 3.0.3)"): on constant_spin — a spin about a principal
axis, where its step is exact in exact arithmetic — the attitude's error grows as N, 0.26 N ε₃₂ |ω| in ω."""
import math

import pytest

from cross_checks.analysis import metrics as M
from cross_checks.core import tolerances as tol

E32, E64 = tol.MACHINE_EPSILON["float32"], tol.MACHINE_EPSILON["float64"]
#: physx:pgs on constant_spin (5 s, |ω| = 3 rad/s): final orientation errors (rad) at N = 250 … 4000 steps.
PGS_CONSTANT_SPIN = ((250, 5.97e-5), (500, 1.387e-4), (1000, 2.220e-4), (2000, 4.987e-4), (4000, 1.009e-3))


@pytest.mark.parametrize("quantity", ["orientation", "angular_velocity"])
def test_float32_rotation_floors_add_roundings_of_one_sign_linearly_and_float64_ones_do_not(quantity):
    n, scale, amp = 4000, 3.0, 2.0
    assert M.roundoff_floor(scale, n, reference_error=0.0, amplification=amp, quantity=quantity,
                            eps=E32) == pytest.approx(E32 * scale * (n + math.sqrt(n) * amp))
    assert M.roundoff_floor(scale, n, reference_error=0.0, amplification=amp,
                            quantity=quantity) == pytest.approx(E64 * scale * math.sqrt(n) * amp)


def test_physx_pgs_round_off_on_a_principal_axis_spin_is_within_float32_floors_only_with_the_linear_term():
    for n, err in PGS_CONSTANT_SPIN:
        floor = M.roundoff_floor(math.pi, n, reference_error=0.0, quantity="orientation", eps=E32)
        assert err <= floor
        # the random-walk term alone (the float64 model) leaves every one of them 10-42× above it
        assert err > 4 * E32 * math.pi * math.sqrt(n)

"""What the fuzz found in the engines and in rbcheck, pinned (docs/fuzz.md "Findings")."""
import numpy as np
import pytest

from cross_checks.analysis.expectations import pair_is_same_arithmetic
from cross_checks.engines import get_adapter
from cross_checks.fuzz.known import explain
from cross_checks.fuzz.pipeline import scenario_of


def _spin(decay, inertia=(0.2, 0.3, 0.4), torque=None):
    spec = {"name": "decay_pair", "duration": 0.5, "dt": 0.01, "body": {"mass": 1.0, "inertia": list(inertia)},
            "initial": {"angular_velocity_body": [0.3, 2.0, 0.5]}, "forces": {}}
    if decay:
        spec["forces"]["angular_velocity_decay"] = 0.98
    return scenario_of(spec)


def _diff(sc, h):
    a = np.asarray(get_adapter("reference").simulate(sc, "expmap_gyro", h, int(round(0.5 / h))).y)
    b = np.asarray(get_adapter("mujoco").simulate(sc, "euler", h, int(round(0.5 / h))).y)
    return float(np.max(np.abs(a[:, 10:13] - b[:, 10:13])))


def test_pre_step_decay_breaks_the_expmap_gyro_mujoco_euler_pair_only_with_a_gyroscopic_term():
    """The engines' harness applies γ before the step, the course after: with angular decay on a tumbling
    asymmetric body the gyroscopic term sees γ twice — a first-order difference (halves with Δt)."""
    sc = _spin(decay=True)
    d1, d2 = _diff(sc, 0.01), _diff(sc, 0.005)
    assert d1 > 1e-6 and 1.6 < d1 / d2 < 2.4
    assert not pair_is_same_arithmetic(sc, "reference:expmap_gyro", "mujoco:euler")
    assert pair_is_same_arithmetic(sc, "mujoco:euler", "pybullet:multibody")
    plain = _spin(decay=False)
    assert _diff(plain, 0.01) < 1e-12
    assert pair_is_same_arithmetic(plain, "reference:expmap_gyro", "mujoco:euler")
    sym = _spin(decay=True, inertia=(0.3, 0.3, 0.3))   # no gyroscopic torque: exact again
    assert _diff(sym, 0.01) < 1e-12
    assert pair_is_same_arithmetic(sym, "reference:expmap_gyro", "mujoco:euler")


def _pybullet_gap(scale):
    sc = scenario_of({"name": "tiny", "duration": 0.1, "dt": 0.001,
                      "body": {"mass": 0.1, "inertia": [scale, 2 * scale, 2.5 * scale]},
                      "initial": {"angular_velocity": [1.0, 2.0, 0.5]}, "forces": {}})
    a = np.asarray(get_adapter("pybullet").simulate(sc, "maximal", 0.001, 100).y)
    b = np.asarray(get_adapter("pybullet").simulate(sc, "multibody", 0.001, 100).y)
    return sc, float(np.max(np.abs(a[:, 10:13] - b[:, 10:13])))


def test_pybullet_maximal_gyroscopic_step_fails_below_bullets_solve33_threshold():
    """Maximal (implicit gyroscopic term) and multibody (explicit) differ by O(Δt) (7e-5 rad/s here) —
    until I1 I2 I3 drops below 2.2e-16 kg³m⁶, where btMatrix3x3::solve33 stops inverting: 1000× more."""
    small, gap_small = _pybullet_gap(1e-6)
    normal, gap_normal = _pybullet_gap(1e-5)
    assert gap_normal < 2e-4
    assert gap_small > 100 * gap_normal
    v = {"variants": ["pybullet:maximal"], "property": "free_running_order"}
    assert "solve33" in explain(small, v)
    assert explain(normal, v) == ""
    assert explain(small, {"variants": ["pybullet:multibody"], "property": "free_running_order"}) == ""

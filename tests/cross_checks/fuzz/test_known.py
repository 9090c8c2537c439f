"""Documented engine behaviours a counterexample may show (fuzz.known), pinned against the engine."""
import numpy as np

from cross_checks.engines import get_adapter
from cross_checks.fuzz.known import explain
from cross_checks.fuzz.pipeline import scenario_of


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

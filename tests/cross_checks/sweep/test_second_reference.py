"""The second reference: Drake's error-controlled solution agrees with the primary (closed form or DOP853)
within the accuracies the two MEASURE; a planted error in either is caught; the comparison's arithmetic
is checked by hand; without Drake there is no record and nothing else changes."""
import dataclasses
import functools

import numpy as np
import pytest

from cross_checks.core.quantities import QUANTITIES
from cross_checks.scenario import catalog_names, load_scenario
from cross_checks.sweep import second_reference as SR
from cross_checks.sweep.jobs import job_dts

pytest.importorskip("pydrake", reason="drake is not installed (pip install -e '.[drake]')")


def _primary(sc):
    from cross_checks.scenario.references import reference_solution
    t = np.unique(np.concatenate([dt * np.arange(sc.n_steps(dt) + 1) for dt in job_dts(sc)]))
    y, label = reference_solution(sc, t)
    return t, y, label


def _record(sc, primary=None, cache_root=None):
    """The sweep's record for ``sc`` with ``primary`` (t, y, label) as its primary reference; measured
    as the sweep measures it (its error and the error amplification)."""
    from cross_checks.core.quantities import quantity_scales
    from cross_checks.scenario.references import error_amplification, reference_error
    t, y, label = primary or _primary(sc)
    scales = quantity_scales(y)
    measured = {"reference_error": reference_error(sc, y[-1], label, scales),
                "amplification": error_amplification(sc, scales)}
    return SR.second_reference(sc, t, y, label, measured, cache_root, use_cache=True)


@functools.cache
def _catalog_record(name):
    return _record(load_scenario(name))


# Cheap scenarios covering a closed-form tumble, DOP853 with torques and off-COM forces, and decay.
@pytest.mark.parametrize("name", ["tennis_racket", "applied_torque", "velocity_decay"])
def test_the_two_references_agree_within_their_measured_accuracies(name):
    rec = _catalog_record(name)
    assert rec["agrees"], (rec["distance"], rec["stated_accuracy"])
    assert rec["label"].startswith("drake 1.51.1 runge_kutta5") and rec["target_accuracy"] == 1e-13
    for q in QUANTITIES:
        assert rec["stated_accuracy"][q] == rec["primary_accuracy"][q] + rec["second_accuracy"][q]


@pytest.mark.slow
@pytest.mark.parametrize("name", catalog_names())
def test_the_two_references_agree_on_every_catalog_scenario(name):
    rec = _record(load_scenario(name))
    assert rec["agrees"], (rec["distance"], rec["stated_accuracy"])


def test_the_stated_accuracy_is_tight_enough_to_catch_a_wrong_motion():
    # tennis_racket: what the pair claims (measured 3e-9 rad) is far below what a 1e-6 relative change
    # of one moment does to the motion over 10 s (measured below)
    rec = _catalog_record("tennis_racket")
    assert rec["stated_accuracy"]["orientation"] < 1e-8
    assert rec["distance"]["orientation"] < rec["stated_accuracy"]["orientation"]


def _with_inertia_scaled(sc, factor):
    body = sc.problem.body
    new_body = dataclasses.replace(body, inertia_B=body.inertia_B * np.array([1.0, factor, 1.0]))
    return dataclasses.replace(sc, problem=dataclasses.replace(sc.problem, body=new_body))


def test_a_primary_reference_of_a_slightly_wrong_body_is_caught():
    sc = load_scenario("tennis_racket")
    wrong = _primary(_with_inertia_scaled(sc, 1.0 + 1e-6))    # the intermediate moment 1e-6 too large
    rec = _record(sc, primary=wrong)
    assert not rec["agrees"] and "orientation" in rec["disagreeing"]


def test_a_dop853_primary_of_slightly_wrong_gravity_is_caught():
    sc = load_scenario("applied_torque")
    fm = sc.problem.forces
    wrong = dataclasses.replace(sc, problem=dataclasses.replace(
        sc.problem, forces=dataclasses.replace(fm, gravity_W=np.asarray(fm.gravity_W) * (1.0 + 1e-9))))
    rec = _record(sc, primary=_primary(wrong))    # ½ Δg t² = 2e-8 m at 2 s
    assert not rec["agrees"] and "position" in rec["disagreeing"]


def test_a_second_reference_of_a_slightly_wrong_body_is_caught(monkeypatch):
    from cross_checks.engines.worlds import drake as dkw

    def wrong(mass_kg, moments, R_BP=None, com_B=None):   # every moment 1e-6 too large (diagonal inertia)
        from pydrake.multibody.tree import RotationalInertia, SpatialInertia
        return SpatialInertia.MakeFromCentralInertia(
            float(mass_kg), np.zeros(3), RotationalInertia(*(np.asarray(moments) * (1.0 + 1e-6))))

    monkeypatch.setattr(dkw, "spatial_inertia", wrong)   # the adapter's body is its world's
    rec = _record(load_scenario("applied_torque"))
    assert not rec["agrees"] and {"orientation", "angular_velocity"} <= set(rec["disagreeing"])


def test_the_comparison_by_hand():
    y = np.zeros((3, 13))
    y[:, 6] = 1.0
    second = y.copy()
    second[1, 0] = 3e-9                      # position off by 3e-9 m at one sample
    check = second.copy()
    check[2, 0] = 1e-9                       # the looser Drake solution 1e-9 m from the tighter one
    rec = SR.compare_references(y, second, check, primary_error={q: 1e-10 for q in QUANTITIES},
                                amplification={}, primary_steps=1, second_steps=1)
    eps = 2.2e-16
    assert rec["distance"]["position"] == 3e-9 and rec["distance"]["orientation"] == 0.0
    # primary: 1e-10 + ε·scale·(N + √N); second: 1e-9 + ε·scale·(N + √N), scale 1, N 1
    assert rec["primary_accuracy"]["position"] == pytest.approx(1e-10 + 2 * eps, rel=1e-12)
    assert rec["second_accuracy"]["position"] == pytest.approx(1e-9 + 2 * eps, rel=1e-12)
    assert not rec["agrees"] and rec["disagreeing"] == ["position"]
    check[2, 0] = 3e-9
    assert SR.compare_references(y, second, check, primary_error={q: 1e-10 for q in QUANTITIES},
                                 amplification={}, primary_steps=1, second_steps=1)["agrees"]


def test_the_drake_solutions_are_cached(tmp_path, monkeypatch):
    sc = load_scenario("projectile")
    first = _record(sc, cache_root=str(tmp_path))
    from cross_checks.engines import drake_reference

    def refuse(*a, **k):
        raise AssertionError("Drake ran again instead of reading the cache")

    monkeypatch.setattr(drake_reference, "drake_solution", refuse)
    assert _record(sc, cache_root=str(tmp_path))["distance"] == first["distance"]


def test_without_drake_there_is_no_record(monkeypatch):
    from cross_checks.engines import drake_engine
    monkeypatch.setattr(drake_engine, "pydrake", None)
    monkeypatch.setattr(drake_engine, "_IMPORT_ERROR", ImportError("No module named 'pydrake'"))
    sc = load_scenario("projectile")
    t, y, label = _primary(sc)
    assert SR.second_reference(sc, t, y, label, {}, None, True) is None


def test_a_drake_failure_is_reported_not_raised(monkeypatch):
    from cross_checks.engines import drake_reference

    def boom(*a, **k):
        raise RuntimeError("Simulator stopped")

    monkeypatch.setattr(drake_reference, "drake_solution", boom)
    sc = load_scenario("projectile")
    t, y, label = _primary(sc)
    rec = SR.second_reference(sc, t, y, label, {}, None, True)
    assert rec["agrees"] is None and rec["error"] == "RuntimeError: Simulator stopped"


def test_a_sweep_whose_references_disagree_exits_1_saying_so():
    from cross_checks.cli.sweep import _gate_failures
    rec = {"label": "drake X", "agrees": False, "disagreeing": ["orientation"]}
    summary = {"scenarios": [{"name": "tennis_racket", "reference": "analytic", "second_reference": rec},
                             {"name": "projectile", "reference": "analytic", "second_reference": None}]}
    assert _gate_failures(summary) == ["the references of tennis_racket disagree: analytic and drake "
                                       "X differ in orientation beyond their measured accuracies"]
    rec["agrees"] = None     # Drake failed: not a disagreement (the record says why)
    assert _gate_failures(summary) == []

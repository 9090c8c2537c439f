"""The pieces of cross_checks.engines.base the adapters share: the variant check, the grouped batch runner,
the single request, ModuleAdapter's forwarding, one_step on rows of any shape."""
import sys
import types

import numpy as np
import pytest

from cross_checks.engines import base
from cross_checks.engines.base import EngineError, ModuleAdapter, RunRequest, Variant


def test_an_unknown_variant_is_refused_with_the_engine_s_variants():
    base.check_variant("mysim", {"euler": 1, "rk4": 2}, "euler")
    with pytest.raises(ValueError, match=r"unknown mysim variant 'rk2'; variants: euler, rk4"):
        base.check_variant("mysim", {"euler": 1, "rk4": 2}, "rk2")


def test_one_request_raises_the_engine_error_of_its_run():
    ok = base.one_request(lambda v, rs: [f"{v} {rs[0].dt_s} {rs[0].n_steps}"], "sc", "euler", 0.5, 3.0)
    assert ok == "euler 0.5 3"
    with pytest.raises(EngineError, match="refused"):
        base.one_request(lambda v, rs: [EngineError("refused")], "sc", "euler", 0.5, 3)


def test_a_module_adapter_forwards_to_its_module_s_functions_looked_up_when_called(monkeypatch):
    mod = types.ModuleType("fake_engine_for_test")
    mod.version = lambda: "1.2"
    mod.simulate = lambda sc, v, dt, n: ("simulate", sc, v, dt, n)
    mod.one_step = lambda sc, v, dt, y: np.asarray(y) + 1
    monkeypatch.setitem(sys.modules, mod.__name__, mod)
    Adapter = type("Adapter", (ModuleAdapter,), {"__module__": mod.__name__, "name": "fake",
                                                 "variants": {"euler": Variant(1, "e")}})
    a = Adapter()
    assert a.version() == "1.2" and a.has_one_step
    assert a.simulate("sc", "euler", 0.1, 2) == ("simulate", "sc", "euler", 0.1, 2)
    assert a.one_step("sc", "euler", 0.1, [1.0]).tolist() == [2.0]
    # without a simulate_many of its own, the runs are simulate's, one by one
    assert a.simulate_many("euler", [RunRequest("a", 0.1, 1)]) == [("simulate", "a", "euler", 0.1, 1)]
    mod.simulate_many = lambda v, rs: ["batched"] * len(rs)
    assert a.simulate_many("euler", [RunRequest("a", 0.1, 1)] * 2) == ["batched", "batched"]




def test_an_invariance_finding_is_narrow_and_says_why():
    """engines.base.InvarianceFinding: one transform kind, at least one size range of that kind, the
    quantities it moves and the reason; matched only within its ranges (a size computed from a vector carries
    a few roundings: 10 km along (2, −3, 6)/7 is 9999.999999999998 m)."""
    from cross_checks.scenario.transforms import Scale, Translation
    f = base.InvarianceFinding("translation", (("distance_m", 1e3, 1e4),), "why", ("position",))
    d = np.array([2.0, -3.0, 6.0]) / 7.0
    assert f.matches(Translation(tuple(1e4 * d))) and f.matches(Translation(tuple(1e3 * d)))
    assert not f.matches(Translation(tuple(10.0 * d))) and not f.matches(Scale(0.01, 0.01))
    assert f.range_text() == "distance_m 1000–10000"
    bad = [(("rotate", (("angle_deg", 0, 1),), "why"), "transform must be one of"),
           (("scale", (), "why"), "within must name at least one of scale's sizes"),
           (("scale", (("angle_deg", 0, 1),), "why"), "size one of k, mu"),
           (("scale", (("k", 1.0, 0.1),), "why"), "low <= high"),
           (("scale", (("k", 0.1, 1.0),), " "), "reason must be the sentence"),
           (("scale", (("k", 0.1, 1.0),), "why", ("speed",)), "quantities must be a non-empty tuple")]
    for args, words in bad:
        with pytest.raises(ValueError, match=words):
            base.InvarianceFinding(*args)
    with pytest.raises(ValueError, match="invariance_findings must be a tuple of InvarianceFinding"):
        base.Traits(invariance_findings=["scale"])

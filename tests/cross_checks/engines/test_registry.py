"""The engine registry: one way in (the rbcheck.engines entry points, rbcheck's own engines included),
declared orders reaching the verdicts, and plug-ins that cannot load listed with the reason."""
import pytest

from cross_checks import engines
from cross_checks.analysis.expectations import expectation, nominal_order
from cross_checks.cli import main
from cross_checks.engines import resolve
from cross_checks.engines.base import EngineAdapter, Variant
from cross_checks.scenario import load_scenario
from tests.helpers.byo import make_fake_distribution


@pytest.fixture(autouse=True)
def _fresh_registry():
    engines.reset_registry()
    yield
    engines.reset_registry()


def test_built_in_engines_come_in_through_rbcheck_s_own_entry_points():
    entries = {e.name: e for e in engines.engine_entries()}
    assert list(entries)[:3] == ["reference", "mujoco", "pybullet"]
    for name, cls in (("reference", "cross_checks.engines.reference:ReferenceAdapter"),
                      ("mujoco", "cross_checks.engines.mujoco_engine:MujocoAdapter"),
                      ("pybullet", "cross_checks.engines.pybullet_engine:PybulletAdapter")):
        assert entries[name].source == f"entry point {name} = {cls} (rbcheck)"
        assert isinstance(entries[name].adapter, EngineAdapter) and entries[name].adapter.has_one_step


def test_a_variant_of_an_unknown_engine_says_how_to_add_one():
    with pytest.raises(engines.UnknownVariant, match=r"unknown engine 'mysim'; engines: reference, mujoco, "
                                                     r"pybullet.*\(add your own with --engine-file FILE\)"):
        engines.split_variant("mysim:euler")


def test_a_user_engine_s_declared_order_is_the_order_its_verdicts_expect(tmp_path):
    (tmp_path / "e.toml").write_text('name = "second"\n[variants.mid]\norder = 2\ndescription = "mid-point"\n'
                                     'command = ["true", "{scenario_json}", "{out_csv}"]\n')
    sc = load_scenario("tennis_racket")
    assert nominal_order(resolve("second:mid")) is None
    with engines.engine_files_registered([tmp_path / "e.toml"]):
        assert nominal_order(resolve("second:mid")) == 2.0
        e = expectation(sc, resolve("second:mid"), "orientation")
        assert (e.verdict, e.order) == ("converges", 2.0) and e.reason == "second:mid is an order-2 scheme"
        assert expectation(sc, resolve("second:mid"), "orientation", "one_step").order == 3.0
        assert not engines.has_one_step("second:mid")
    assert nominal_order(resolve("second:mid")) is None


BROKEN_PLUGINS = "\n".join([
    "fakesim = rbcheck_fake_engine:FakeSimAdapter",
    "ghost = rbcheck_no_such_module:Adapter",          # the module is not installed
    "renamed = rbcheck_fake_engine:FakeSimAdapter",    # the class calls itself fakesim
    "mujoco = rbcheck_fake_engine:FakeSimAdapter",     # takes a built-in engine's name
])


def test_plug_ins_that_cannot_load_are_listed_unavailable_with_the_reason(tmp_path, monkeypatch, capsys):
    site = make_fake_distribution(tmp_path / "site", entry_points=BROKEN_PLUGINS, dist="odd_engines")
    monkeypatch.syspath_prepend(str(site))
    engines.reset_registry()
    infos = {v.name: v for v in engines.all_variants()}
    assert infos["fakesim:euler"].available and infos["fakesim:euler"].order == 1.0
    assert infos["mujoco:euler"].available and infos["mujoco:euler"].source.endswith("(rbcheck)")
    assert "ModuleNotFoundError: No module named 'rbcheck_no_such_module'" in infos["ghost:*"].reason
    assert "its adapter's name is 'fakesim', not 'renamed'" in infos["renamed:*"].reason
    assert "the engine name 'mujoco' is already registered by entry point mujoco" in infos["mujoco:*"].reason
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "ghost:*" in out and "UNAVAILABLE" in out and "fakesim: from entry point fakesim" in out
    assert main(["sweep", "projectile", "--engines", "ghost", "--out", str(tmp_path / "r")]) == 2
    assert "--engines ghost: ghost: cannot load rbcheck_no_such_module:Adapter" in capsys.readouterr().err


class _NoVersion(EngineAdapter):
    name = "noversion"
    variants = {"v": Variant(1, "needs a package that is missing")}

    def version(self):
        raise ImportError("No module named 'somesim'")

    def simulate(self, scenario, variant, dt_s, n_steps):
        raise AssertionError("never reached: version() already says the engine cannot run")


def test_an_engine_whose_package_is_missing_is_unavailable_not_fatal():
    engines.register_adapter(_NoVersion(), "test")
    info = next(v for v in engines.all_variants() if v.engine == "noversion")
    assert not info.available and info.reason == "noversion cannot be imported: No module named 'somesim'"
    with pytest.raises(engines.EngineUnavailable):
        engines.get_adapter("noversion")


@pytest.mark.parametrize("adapter_attrs, words", [
    ({"variants": {}}, "declares no variants"),
    ({"variants": {"v": (1, "d")}}, "must be a Variant(order, description)"),
    ({"variants": {"V-1": Variant(1)}}, "variant name 'V-1' must match"),
])
def test_an_adapter_that_breaks_the_interface_is_refused(adapter_attrs, words):
    cls = type("Bad", (_NoVersion,), {"name": "bad", **adapter_attrs})
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
        engines.register_adapter(cls(), "test")


@pytest.mark.parametrize("order", [0, -1, True, float("nan"), "1", 21])
def test_a_declared_order_must_be_a_positive_number(order):
    with pytest.raises(ValueError, match="order must be a number in"):
        Variant(order)


def test_resolved_variant_carries_what_its_engine_declares_and_stays_its_name():
    """A variant is resolved once (engines.resolve) and passed down: it equals, hashes, formats and pickles as
    its name, and carries the declared order, traits (an imitation's, when it imitates), precision, rounding
    unit and one-step mode — each equal to what the registry's one-off lookups say."""
    import pickle

    from cross_checks.core.tolerances import MACHINE_EPSILON
    from cross_checks.engines import Resolved, declared_order, declared_traits, has_one_step, resolve
    for name in ("reference:rk4", "mujoco:euler", "pybullet:multibody"):
        v = resolve(name)
        assert isinstance(v, Resolved) and v == name and hash(v) == hash(name) and f"{v}" == name
        assert {v: 1}[name] == 1 and resolve(v) is v
        assert (v.engine, v.variant) == tuple(name.split(":"))
        assert v.order == declared_order(name) and v.traits == declared_traits(name)
        assert v.precision == v.traits.precision == "float64" and v.one_step == has_one_step(name)
        assert v.rounding_unit == MACHINE_EPSILON["float64"] * v.traits.rounding_factor
        back = pickle.loads(pickle.dumps(v))
        assert isinstance(back, Resolved) and back == v and back.traits == v.traits and back.order == v.order
        assert v.adapter.name == v.engine and v.known
    unknown = resolve("nobody:knows")   # a name from someone else's results: the cautious defaults
    from cross_checks.engines.base import DEFAULT_TRAITS
    assert unknown.order is None and unknown.traits == DEFAULT_TRAITS and not unknown.known
    assert not unknown.one_step

"""Expectations are decided from the variant's traits and the scenario's measured physics, never its name."""
import numpy as np
import pytest

from cross_checks import engines
from cross_checks.analysis.expectations import DEFAULT_TRAITS, expectation, nominal_order, traits
from cross_checks.core.quantities import QUANTITIES
from cross_checks.engines import all_variants, available_variants, declared_traits, resolve, run_variant
from cross_checks.engines.base import EngineAdapter, Traits, Variant
from cross_checks.scenario import catalog_names, catalog_path, load_scenario, parse_scenario

#: Every variant that declares its traits (Variant.traits): the built-in engines' variants, installed here.
VARIANT_TRAITS = {v.name: declared_traits(v.name)
                  for v in all_variants() if declared_traits(v.name) is not None}


def test_every_built_in_variant_has_a_nominal_order_and_traits():
    built_in = [v.name for v in all_variants() if v.engine in ("reference", "mujoco", "pybullet")]
    assert len(built_in) == 23   # 16 reference variants (8 gyroscopic: docs/gyro_integrators.md)
    for v in built_in:
        assert (nominal_order(resolve(v)) in (1.0, 2.0, 4.0) and declared_traits(v) is not None
                and traits(resolve(v)) == declared_traits(v))


def test_an_unknown_variant_gets_the_documented_default():
    assert traits(resolve("mysim:euler")) == DEFAULT_TRAITS and nominal_order(resolve("mysim:euler")) is None
    e = expectation(load_scenario("projectile"), resolve("mysim:euler"), "position")
    assert e.verdict == "converges" and e.order is None


@pytest.mark.parametrize("name", ["tennis_racket", "tumbling_box", "particle_body", "symmetric_top"])
def test_course_is_expected_not_to_converge_in_rotation_on_gyroscopic_bodies(name):
    sc = load_scenario(name)
    for q in ("orientation", "angular_velocity"):
        e = expectation(sc, resolve("reference:course"), q)
        assert e.verdict == "does_not_converge" and "gyroscopic" in e.reason
    assert expectation(sc, resolve("reference:course"), "position").order == 1.0   # translation is decoupled
    assert expectation(sc, resolve("reference:course_gyro"), "orientation").order == 1.0


def test_course_converges_where_the_gyroscopic_term_vanishes():
    for name in ("constant_spin", "projectile", "linear_drag", "spring_oscillator"):
        sc = load_scenario(name)
        assert all(expectation(sc, resolve("reference:course"), q).verdict == "converges" for q in QUANTITIES)


def test_course_position_fails_when_rotation_drives_translation():
    assert (expectation(load_scenario("spring_pendulum"), resolve("reference:course"), "position").verdict
            == "does_not_converge")
    assert (expectation(load_scenario("applied_torque"), resolve("reference:course"), "position").verdict
            == "converges")


def test_every_variant_is_expected_to_converge_under_velocity_decay():
    # Decay is the rate k = −ln γ / dt in every variant: each converges at its order to the damped motion —
    # first order for an engine that holds the applied forces (the decay force among them) over its stages.
    sc = load_scenario("velocity_decay")
    for v in VARIANT_TRAITS:
        order = 1.0 if VARIANT_TRAITS[v].forces_held else nominal_order(resolve(v))
        for q in QUANTITIES:
            e = expectation(sc, resolve(v), q)
            assert e.verdict == "converges" and e.order == order, (v, q, e)


@pytest.mark.parametrize("name", catalog_names())
def test_every_catalog_scenario_has_an_expectation_for_every_variant(name):
    sc = load_scenario(name)
    for v in VARIANT_TRAITS:
        for q in QUANTITIES:
            e = expectation(sc, resolve(v), q)
            assert e.verdict in ("converges", "does_not_converge", "pre_asymptotic"), (v, q, e)
            assert (e.order is not None) == (e.verdict == "converges")
            local = expectation(sc, resolve(v), q, "one_step")
            # the local order p + 1 is claimed wherever the variant has the physics, pre-asymptotic or not
            assert local.verdict == (None if e.verdict == "does_not_converge" else "converges")


def _renamed(name, new_name, **replace):
    text = catalog_path(name).read_text(encoding="utf-8").replace(f'name = "{name}"', f'name = "{new_name}"')
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new)
    return parse_scenario(text, f"{new_name}.toml")


@pytest.mark.parametrize("name", ["tumbling_box", "tennis_racket",
                                  pytest.param("spring_pendulum", marks=pytest.mark.slow)])
def test_no_rule_names_a_scenario(name):
    # The same physics under another name: the same expectations, word for word.
    a, b = load_scenario(name), _renamed(name, "my_own_body")
    for v in VARIANT_TRAITS:
        for q in QUANTITIES:
            assert expectation(a, resolve(v), q) == expectation(b, resolve(v), q), (v, q)


def test_a_gentle_file_named_tumbling_box_gets_the_verdicts_its_physics_implies():
    gentle = _renamed("tumbling_box", "tumbling_box", **{
        "angular_velocity_body = [0.1, 5.0, 0.1]": "angular_velocity_body = [0.3, 0.5, 0.2]",
        "duration = 10.0": "duration = 2.0"})
    for v in ("reference:explicit_euler", "reference:implicit_euler"):
        for q in QUANTITIES:
            e = expectation(gentle, resolve(v), q)
            assert e.verdict == "converges" and e.order == 1.0, (v, q, e.reason)
    wild = load_scenario("tumbling_box")
    e = expectation(wild, resolve("reference:explicit_euler"), "orientation")
    assert e.verdict == "pre_asymptotic" and "separatrix" in e.reason and "amplifies" in e.reason
    # the body-frame Euler step keeps the separatrix distance (see test_engine_traits): its order is claimed
    assert expectation(wild, resolve("reference:expmap_gyro"), "orientation").order == 1.0
    # translation: a projectile
    assert expectation(wild, resolve("reference:explicit_euler"), "position").order == 1.0


def test_a_pure_spin_gives_no_amplitude_drift_however_fast():
    # ω along a principal axis stays put and the normalised quaternion update has a phase error only:
    # explicit Euler even shows order 2 there. A 10× faster constant_spin is still claimed at order ≥ 1.
    fast = _renamed("constant_spin", "fast_spin", **{"angular_velocity_body = [0.0, 0.0, 3.0]":
                                                     "angular_velocity_body = [0.0, 0.0, 30.0]"})
    for v in ("reference:explicit_euler", "reference:implicit_euler", "mujoco:implicit", "pybullet:maximal"):
        for q in QUANTITIES:
            assert expectation(fast, resolve(v), q).verdict == "converges", (v, q)


def test_chi_applies_to_every_first_order_variant_that_drifts():
    # symmetric_top: the polhode turns at 4 rad/s — χ = ½·16·0.01·10 = 0.8 at the coarsest Δt; the body-frame
    # Euler step drifts by e^{±χ}, which alone would fit 1.14 (explicit) / 0.87 (implicit): still claimed.
    # The whole-state step drifts at the space-cone rate |L|/I1 = 8.1 rad/s (χ = 3.3): no claim.
    top = load_scenario("symmetric_top")
    for v in ("reference:expmap_gyro", "mujoco:euler", "mujoco:implicit", "mujoco:implicitfast",
              "pybullet:multibody", "pybullet:maximal"):
        assert expectation(top, resolve(v), "orientation").order == 1.0, v
    for v in ("reference:explicit_euler", "reference:implicit_euler"):
        e = expectation(top, resolve(v), "orientation")
        assert e.verdict == "pre_asymptotic" and "χ = ω_c²ΔtT/2 from 3.3" in e.reason, e.reason
    # a faster wobble pushes the body-frame schemes out too: ω3 = 8 -> polhode at 8 rad/s, χ = 3.2
    faster = _renamed("symmetric_top", "fast_top", **{"angular_velocity_body = [1.0, 0.5, 4.0]":
                                                     "angular_velocity_body = [1.0, 0.5, 8.0]"})
    for v in ("mujoco:implicit", "pybullet:maximal", "mujoco:euler"):
        assert expectation(faster, resolve(v), "orientation").verdict == "pre_asymptotic", v
    # symplectic (leapfrog) and higher-order schemes are never excused
    assert expectation(faster, resolve("reference:leapfrog"), "orientation").order == 2.0
    assert expectation(faster, resolve("reference:rk4"), "orientation").order == 4.0


def test_an_oscillator_is_claimed_where_the_amplitude_model_allows_it():
    # spring_oscillator: χ = ½·40·0.008·5 = 0.8 at the coarsest Δt, yet the drift alone fits 1.14 / 0.87:
    # within 1 ± 0.15, so order 1 is claimed (the sweep measures 1.14 / 0.88); a stiffer spring is not.
    osc = load_scenario("spring_oscillator")
    for v in ("reference:explicit_euler", "reference:implicit_euler"):
        assert expectation(osc, resolve(v), "position").order == 1.0
    stiff = _renamed("spring_oscillator", "stiff", **{"stiffness = 40.0": "stiffness = 160.0"})
    for v in ("reference:explicit_euler", "reference:implicit_euler"):
        assert expectation(stiff, resolve(v), "position").verdict == "pre_asymptotic"
    # symplectic Euler: no drift
    assert expectation(stiff, resolve("reference:expmap_gyro"), "position").order == 1.0


# --- the traits, pinned on the engines themselves -------------------------------------------------------

FIRST_ORDER_WITH_GYRO = [v for v, tr in VARIANT_TRAITS.items()
                         if nominal_order(resolve(v)) == 1.0 and tr.gyroscopic_term]


def _invariants(sc, y):
    """2E_rot and |L|² in principal axes, and the separatrix distance δ, along states y (T, 13)."""
    from reference_sim.quaternion import quat_conj, rotate
    moments, R_BP = sc.problem.body.principal_axes()
    w_P = rotate(quat_conj(y[:, 6:10]), y[:, 10:13]) @ R_BP
    two_E = np.sum(moments * w_P ** 2, axis=1)
    L2 = np.sum((moments * w_P) ** 2, axis=1)
    return two_E, L2, (two_E * moments[1] - L2) / L2


def _momentum_rounding(variant: str, n_steps: int) -> float:
    """How far |L|² may move in n steps of a step that keeps |L| but rounds: 20 N ε — each step rounds ω by up
    to 10 ulp in one direction (PhysX TGS's √I round trip: 3–10 ulp measured, docs/engine_conventions.md), and
    |L|² doubles a relative error."""
    from cross_checks.analysis.expectations import precision
    from cross_checks.core import tolerances as tol
    return 20.0 * n_steps * tol.MACHINE_EPSILON[precision(resolve(variant))]


@pytest.mark.parametrize("variant", FIRST_ORDER_WITH_GYRO)
def test_rotational_energy_drifts_the_way_the_traits_say(variant):
    # body-frame steps: grows with an explicit, decays with an implicit gyroscopic term; whole-state
    # steps: the other way round (explicit Euler loses rotational energy)
    if variant not in available_variants():
        pytest.skip(f"{variant} unavailable")
    sc = load_scenario("symmetric_top")
    y = run_variant(sc, variant, dt_s=0.01, duration_s=2.0).y
    two_E, L2, _ = _invariants(sc, y)
    if VARIANT_TRAITS[variant].rotation_drift == "momentum":
        # |L| kept; the energy moves towards L²/I₂ (2E at the separatrix): up, about the top's major axis
        moments, _ = sc.problem.body.principal_axes()
        assert abs(L2[-1] / L2[0] - 1.0) <= _momentum_rounding(variant, len(y) - 1), (L2[0], L2[-1])
        assert abs(two_E[-1] / two_E[0] - 1.0) > 10 * _momentum_rounding(variant, len(y) - 1)
        toward = np.sign(L2[0] / moments[1] - two_E[0])
        assert toward == 1.0 and np.sign(two_E[-1] - two_E[0]) == toward, (two_E[0], two_E[-1])
        return
    assert np.sign(two_E[-1] - two_E[0]) == VARIANT_TRAITS[variant].rotation_sign, (two_E[0], two_E[-1])


@pytest.mark.parametrize("variant", FIRST_ORDER_WITH_GYRO)
def test_body_frame_steps_keep_the_separatrix_distance_whole_state_steps_do_not(variant):
    # tumbling_box is 2e-5 from the intermediate-axis separatrix. A body-frame Euler step drifts energy and
    # |L|² together (δ kept); a whole-state step moves δ by thousands of times δ itself. Its rotation, without
    # the throw: the traits are the rotation step's, which the fall does not enter in exact arithmetic — but
    # in float32 a step in world-origin coordinates (Newton's Featherstone) rounds the rotation more the
    # farther the body is (84 m down after 5 s: 2E and |L|² part by 4e-3 of the drift, 1e-4 at the origin;
    # docs/engine_conventions.md "Newton 1.8.0")
    if variant not in available_variants():
        pytest.skip(f"{variant} unavailable")
    text = catalog_path("tumbling_box").read_text(encoding="utf-8")
    at_rest = text.replace("velocity = [-2.0, 2.0, 8.0]\n", "").replace("gravity = [0.0, 0.0, -9.8]",
                                                                         "gravity = [0.0, 0.0, 0.0]")
    assert at_rest.count("0.0, 0.0, 0.0]") == 1 and "-2.0, 2.0, 8.0" not in at_rest
    sc = parse_scenario(at_rest, source="<tumbling_box at rest>")
    y = run_variant(sc, variant, dt_s=2e-3, duration_s=5.0).y
    two_E, L2, delta = _invariants(sc, y)
    moved = float(np.max(np.abs(delta - delta[0])))
    if VARIANT_TRAITS[variant].rotation_drift == "body":
        assert abs(two_E[-1] / two_E[0] - L2[-1] / L2[0]) < 1e-3 * abs(two_E[-1] / two_E[0] - 1) + 1e-12
        assert moved < abs(delta[0]), moved
    elif VARIANT_TRAITS[variant].rotation_drift == "momentum":
        # |L|² kept to its rounding (here the energy's drift is of the same size: the box is slow to turn)
        drift_L2 = float(np.max(np.abs(L2 / L2[0] - 1.0)))
        assert drift_L2 <= _momentum_rounding(variant, len(y) - 1), drift_L2
    else:
        assert VARIANT_TRAITS[variant].rotation_drift == "whole_state"
        assert moved > 100 * abs(delta[0]), moved


# --- same-scheme pairs and the engines' decay harness (found by rbcheck fuzz, docs/fuzz.md) -----------------

def _decaying_spin(decay: bool, inertia=(0.2, 0.3, 0.4)):
    text = f"""
name = "decay_pair"
duration = 0.5
dt = 0.01
[body]
mass = 1.0
inertia = {list(inertia)}
[initial]
angular_velocity_body = [0.3, 2.0, 0.5]
[forces]
angular_velocity_decay = {0.98 if decay else 1.0}
"""
    return parse_scenario(text, source="<test>")


def _expmap_vs_mujoco_euler(sc, h):
    from cross_checks.engines import get_adapter
    n = int(round(0.5 / h))
    a = np.asarray(get_adapter("reference").simulate(sc, "expmap_gyro", h, n).y)
    b = np.asarray(get_adapter("mujoco").simulate(sc, "euler", h, n).y)
    return float(np.max(np.abs(a[:, 10:13] - b[:, 10:13])))


def test_pre_step_decay_breaks_the_expmap_gyro_mujoco_euler_pair_only_with_a_gyroscopic_term():
    """The engines' harness applies γ before the step, the course after: with angular decay on a tumbling
    asymmetric body the gyroscopic term sees γ twice — a first-order difference (halves with Δt)."""
    from cross_checks.analysis.expectations import pair_is_same_arithmetic
    sc = _decaying_spin(decay=True)
    d1, d2 = _expmap_vs_mujoco_euler(sc, 0.01), _expmap_vs_mujoco_euler(sc, 0.005)
    assert d1 > 1e-6 and 1.6 < d1 / d2 < 2.4
    assert not pair_is_same_arithmetic(sc, "reference:expmap_gyro", "mujoco:euler")
    assert pair_is_same_arithmetic(sc, "mujoco:euler", "pybullet:multibody")
    plain = _decaying_spin(decay=False)
    assert _expmap_vs_mujoco_euler(plain, 0.01) < 1e-12
    assert pair_is_same_arithmetic(plain, "reference:expmap_gyro", "mujoco:euler")
    sym = _decaying_spin(decay=True, inertia=(0.3, 0.3, 0.3))   # no gyroscopic torque: exact again
    assert _expmap_vs_mujoco_euler(sym, 0.01) < 1e-12
    assert pair_is_same_arithmetic(sym, "reference:expmap_gyro", "mujoco:euler")


def test_decisions_kept_on_the_physics_are_the_ones_computed_afresh():
    """The expectations kept on a scenario's physics (``ScenarioPhysics.decided``: a fuzz case's or a sweep
    scenario's decisions, reused across variants, quantities and modes) equal those computed on a fresh
    copy of the same physics, reasons included, on every catalog scenario; asked again, from the kept ones."""
    from cross_checks.analysis.physics import physics_from_dict, scenario_physics
    variants = ["reference:course", "reference:course_gyro", "mujoco:euler", "pybullet:multibody",
                "reference:rk4", "reference:explicit_euler", "reference:implicit_euler", "mujoco:implicit",
                "nobody:knows"]
    for name in sorted(set(catalog_names()) - {"spring_pendulum", "applied_torque"}):
        sc = load_scenario(name)
        phys = scenario_physics(sc)
        keys = [(resolve(v), q, m) for v in variants for q in QUANTITIES
                for m in ("free_running", "one_step")]
        fresh = {k: expectation(sc, *k, physics=physics_from_dict(phys.as_dict()), measure_physics=False)
                 for k in keys}
        assert not phys.decided
        for _ in range(2):
            for k in keys:
                assert expectation(sc, *k, physics=phys, measure_physics=False) == fresh[k], (name, k)
        assert phys.decided   # kept, not recomputed


class _HeldForcesRK4(EngineAdapter):
    """An order-4 engine that holds the applied force over its stages (Traits.forces_held), as MuJoCo's RK4
    does with xfrc_applied when nothing evaluates the forces per stage."""
    name = "heldrk4"
    variants = {"rk4": Variant(4, "RK4, applied forces held over the stages",
                               traits=Traits(forces_held=True))}

    def version(self):
        return "test"

    def simulate(self, scenario, variant, dt_s, n_steps):
        raise NotImplementedError


@pytest.fixture
def held_rk4(monkeypatch):
    monkeypatch.setattr(engines, "_user", dict(engines._user))
    engines.register_adapter(_HeldForcesRK4(), "test_expectations.py")
    return "heldrk4:rk4"


@pytest.mark.parametrize("name", ["applied_torque", "spring_pendulum", "velocity_decay", "linear_drag"])
def test_held_forces_make_a_multi_stage_scheme_first_order_where_they_change_within_a_step(held_rk4, name):
    sc = load_scenario(name)
    assert sc.problem.forces.state_dependent or sc.problem.forces.has_decay
    for q in QUANTITIES:
        free, local = expectation(sc, resolve(held_rk4), q), expectation(sc, resolve(held_rk4), q, "one_step")
        assert (free.verdict, free.order, local.order) == ("converges", 1.0, 2.0), (q, free, local)
        assert "holds the applied force" in free.reason
        # MuJoCo's adapter evaluates them per stage
        assert expectation(sc, resolve("mujoco:rk4"), q).order == 4.0


@pytest.mark.parametrize("name", ["constant_spin", "projectile", "tennis_racket"])
def test_held_forces_cost_nothing_where_the_forces_are_constant(held_rk4, name):
    sc = load_scenario(name)
    assert not (sc.problem.forces.state_dependent or sc.problem.forces.has_decay)
    assert {expectation(sc, resolve(held_rk4), q).order for q in QUANTITIES} == {4.0}


class _SecondOrderAttitudeRK4(EngineAdapter):
    """An order-4 engine whose attitude update is second order where ω_B turns (Traits.rotation_order), as
    MJX's RK4 (one exponential of the stages' weighted body-axes ω)."""
    name = "rot2rk4"
    variants = {"rk4": Variant(4, "RK4, attitude by one exponential", traits=Traits(rotation_order=2.0))}

    def version(self):
        return "test"

    def simulate(self, scenario, variant, dt_s, n_steps):
        raise NotImplementedError


def test_a_second_order_attitude_update_is_expected_where_the_body_axes_omega_turns(monkeypatch):
    monkeypatch.setattr(engines, "_user", dict(engines._user))
    engines.register_adapter(_SecondOrderAttitudeRK4(), "test_expectations.py")
    v = "rot2rk4:rk4"
    for name in ("tennis_racket", "particle_body", "tumbling_box"):      # tumbling: ω_B turns
        sc = load_scenario(name)
        for q in ("orientation", "angular_velocity"):
            e = expectation(sc, resolve(v), q)
            assert (e.order, expectation(sc, resolve(v), q, "one_step").order) == (2.0, 3.0), (name, q, e)
            assert "attitude update is order 2" in e.reason
    for name in ("constant_spin", "projectile"):                          # a fixed rotation axis: order 4
        sc = load_scenario(name)
        assert {expectation(sc, resolve(v), q).order for q in QUANTITIES} == {4.0}


# --- long runs (long_run_expectation: from the declared traits only) ---------------------------------------

@pytest.mark.parametrize("variant,keeps,separatrix", [
    ("reference:lp_midpoint", ("energy", "angular_momentum_norm", "angular_momentum"), "kept"),
    ("reference:moser_veselov", ("energy", "angular_momentum_norm", "angular_momentum"), "kept"),
    ("reference:dlm_splitting", ("energy_bounded", "angular_momentum_norm", "angular_momentum"), "kept"),
    ("reference:buss_augmented", ("angular_momentum_norm", "angular_momentum"), None),
    ("reference:jolt_gyro", ("angular_momentum_norm",), "toward_intermediate"),
    ("reference:implicit_gyro_body", (), None), ("reference:rk4", (), None), ("mujoco:euler", (), None),
    ("pybullet:maximal", (), None),
])
def test_what_each_variant_is_expected_to_keep_on_a_long_run(variant, keeps, separatrix):
    from cross_checks.analysis.expectations import long_run_expectation
    e = long_run_expectation(resolve(variant))
    assert (e.keeps, e.separatrix) == (keeps, separatrix), e.reason
    assert e.reason


def test_keeps_names_only_known_invariants():
    from cross_checks.engines.base import Traits
    with pytest.raises(ValueError, match="keeps"):
        Traits(keeps=("momentum",))


# --- Bullet's gyroscopic clamp (Traits.gyroscopic_clamp_N_m; found by rbcheck fuzz, seed 0, batch 0) --------

#: A fast spin of a large body: |ω × I ω| reaches 227 N m, over twice Bullet's 100 N m clamp.
CLAMPED = '''
name = "clamped"
duration = 0.5
dt = 0.002
dt_ladder = [0.004, 0.002, 0.001]
[body]
mass = 1.0
inertia = [10.0, 20.0, 30.0]
[initial]
angular_velocity = [2.0, 10.0, 1.0]
'''


def test_where_bullets_clamp_acts_the_clamped_step_is_expected_not_to_converge():
    from cross_checks.analysis.expectations import expectation, gyroscopic_clamp_acts
    from cross_checks.scenario import load_scenario, parse_scenario
    sc = parse_scenario(CLAMPED)
    worst = gyroscopic_clamp_acts(sc, resolve("reference:explicit_gyro_clamped"))
    # closed form at t = 0: |ω × I ω| with ω = (2, 10, 1), I ω = (20, 200, 30)
    assert worst >= float(np.linalg.norm(np.cross([2.0, 10.0, 1.0], [20.0, 200.0, 30.0]))) - 1e-9
    e = expectation(sc, resolve("reference:explicit_gyro_clamped"), "angular_velocity")
    assert e.verdict == "does_not_converge" and "100 N m" in e.reason
    expmap = resolve("reference:expmap_gyro")
    assert expectation(sc, expmap, "angular_velocity").verdict != "does_not_converge"
    assert gyroscopic_clamp_acts(sc, resolve("reference:expmap_gyro")) is None           # no clamp declared
    racket = load_scenario("tennis_racket")                                      # |ω × I ω| ≤ 14 N m there
    assert gyroscopic_clamp_acts(racket, resolve("reference:explicit_gyro_clamped")) is None


def test_the_sweep_agrees_that_the_clamped_step_does_not_converge_there(tmp_path):
    from cross_checks.scenario import parse_scenario
    from cross_checks.sweep import run_sweep
    from tests.helpers.sweeps import private_cache
    with private_cache(tmp_path / "cache"):
        summary = run_sweep([parse_scenario(CLAMPED)], ["reference:explicit_gyro_clamped"], tmp_path / "res",
                            jobs=1)
    recs = {r["quantity"]: r for r in summary["convergence"]}
    for q in ("orientation", "angular_velocity"):
        assert recs[q]["verdict"] == "does_not_converge" and recs[q]["matches_expectation"] is True, recs[q]


def test_the_invariance_findings_declared_are_the_engines_measured_ones_and_narrow():
    """PyBullet maximal declares its small-body gyroscopic drop at the small scale only (k = 0.01, μ ≤ 0.02:
    Bullet's solve33 threshold), Brax positional its position drift 1–10 km out only
    (docs/engine_conventions.md, "Invariance"); every other transform of theirs, and every other variant,
    declares nothing."""
    from cross_checks.analysis.expectations import invariance_finding
    from cross_checks.scenario.transforms import Scale, Translation, default_transforms
    for t in default_transforms():
        small = t.kind == "scale" and t.parameters["k"] == 0.01
        far = t.kind == "translation" and t.parameters["distance_m"] >= 999.0
        assert (invariance_finding(resolve("pybullet:maximal"), t) is not None) == small, t.label
        assert (invariance_finding(resolve("brax:positional"), t) is not None) == far, t.label
        for v in ("pybullet:multibody", "brax:generalized", "mujoco:euler", "jaxsim:rk4", "reference:rk4"):
            assert invariance_finding(resolve(v), t) is None, (v, t.label)
    assert invariance_finding(resolve("pybullet:maximal"), Scale(0.01, 0.05)) is None   # 0.05 keeps it
    assert invariance_finding(resolve("brax:positional"), Translation((0.0, 0.0, 2e4))) is None
    f = invariance_finding(resolve("brax:positional"), Translation((0.0, 0.0, 1e3)))
    assert f.quantities == ("position", "velocity") and "project_xd" in f.reason
    # Drake's implicit Euler under the COM offset (its origin step; measured on tumbling_box), nothing else
    from cross_checks.scenario.transforms import ComOffset
    for t in default_transforms():
        declared = invariance_finding(resolve("drake:implicit_euler"), t) is not None
        assert declared == (t.kind == "com_offset"), t.label
        assert invariance_finding(resolve("drake:semi_explicit_euler"), t) is None
    assert invariance_finding(resolve("drake:implicit_euler"), ComOffset(3.0)) is None

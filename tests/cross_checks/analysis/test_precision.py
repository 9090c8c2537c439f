"""The precision model (docs/verdicts.md, "Precision"): a variant declares the floating-point format it
computes in (Traits.precision); its round-off floors scale with that format's ε and a float32 variant is
judged on a ladder that reaches coarser steps. Shown on float32 schemes (tests/helpers/float32.py: the
reference's schemes with their state stored in float32): the correct ones pass the sweep's gates, the
same schemes judged with float64 floors would not, and float32 schemes with a planted bug
(tests/mutants.py) are still caught."""
import math
import re

import numpy as np
import pytest

from cross_checks.analysis import metrics as M
from cross_checks.analysis.expectations import (
    characteristic_rate_sq,
    judged_ladder_s,
    machine_epsilon,
    nominal_order,
    precision,
    traits,
)
from cross_checks.cli.sweep import _gate_failures
from cross_checks.core import tolerances as tol
from cross_checks.engines import available_variants, resolve
from cross_checks.engines.base import Traits
from cross_checks.scenario import catalog_names, catalog_path, load_scenario, parse_scenario
from cross_checks.sweep import run_sweep
from tests.helpers.float32 import Float32Adapter, register, to_float32
from tests.mutants import MUTANTS

pytestmark = pytest.mark.usefixtures("isolated_cache")

BY_NAME = {m.name: m for m in MUTANTS}
SCHEMES = ("reference:expmap_gyro", "reference:midpoint", "reference:rk4")
#: forces that turn with the body (applied_torque), a spring on a rotating body (spring_pendulum), and a free
#: tumble near the intermediate axis (tennis_racket: round-off amplified by the motion); the default run takes
#: the longer two over a shorter time and three rungs (the slow test, the catalog as it is)
QUICK_SCENARIOS = ("applied_torque", "spring_pendulum", "tennis_racket")
SHORTER = {"spring_pendulum": (2.0, "[0.008, 0.004, 0.002]"), "tennis_racket": (3.0, "[0.01, 0.005, 0.0025]"),
           "particle_body": (2.0, "[0.004, 0.002, 0.001]")}


def _scenario(name):
    """The catalog scenario ``name``, over SHORTER's duration and ladder where it has one."""
    if name not in SHORTER:
        return load_scenario(name)
    duration, ladder = SHORTER[name]
    text = catalog_path(name).read_text()
    text = re.sub(r"(?m)^duration = .*$", f"duration = {duration!r}", text)
    text = re.sub(r"(?m)^dt_ladder = .*$", f"dt_ladder = {ladder}", text)
    return parse_scenario(text, f"{name} (shorter)")
#: planted bugs of every kind (a stage weight, the gyroscopic sign, a frame mix-up of a torque, of the lever
#: arms and of ω in the attitude update, a stage at the wrong point), each on the scenario that exposes it
F32_MUTANTS = ("rk4_wrong_stage_weight", "gyroscopic_sign_flipped", "body_torque_in_world_axes",
               "lever_arms_not_rotated", "course_quaternion_on_the_right", "midpoint_stage_at_full_step")


def _sweep(tmp_path, scenarios, variants, load=_scenario):
    return run_sweep([load(s) for s in scenarios], list(variants), tmp_path / "out", jobs=1,
                     use_cache=False, progress=False, second_reference=False)


def test_precision_is_float64_or_float32():
    assert Traits().precision == "float64" and Traits(precision="float32").precision == "float32"
    with pytest.raises(ValueError, match="precision"):
        Traits(precision="float16")
    assert tol.MACHINE_EPSILON["float32"] == float(np.finfo(np.float32).eps)
    assert tol.MACHINE_EPSILON["float64"] == pytest.approx(np.finfo(np.float64).eps, rel=0.01)


#: The engines that step in single precision (their documentation and their pinned dtypes: Rapier's "3D, f32"
#: build, PhysX's PxReal, Warp's float32 kernels); every other shipped engine computes in float64.
FLOAT32_ENGINES = ("rapier", "physx", "mujoco_warp", "newton")


def test_every_shipped_variant_declares_its_precision_and_float64_keeps_its_scenarios_ladder():
    for v in available_variants():
        engine = v.split(":", 1)[0]
        if engine in FLOAT32_ENGINES and precision(resolve(v)) == "float32":
            r = resolve(v)
            assert machine_epsilon(r) == tol.MACHINE_EPSILON["float32"] * traits(r).rounding_factor
            for name in catalog_names():   # the float32 ladder extends the scenario's to coarser steps only
                sc = load_scenario(name)
                ladder = judged_ladder_s(sc, resolve(v))
                assert ladder[-len(sc.dt_ladder_s):] == tuple(sorted(sc.dt_ladder_s, reverse=True))
            continue
        assert engine not in FLOAT32_ENGINES[:3], v   # Rapier, PhysX and MuJoCo Warp have no float64 step
        assert precision(resolve(v)) == "float64" and traits(resolve(v)).rounding_factor == 1.0
        assert machine_epsilon(resolve(v)) == tol.ROUNDOFF_PER_STEP_REL
        for name in catalog_names():
            sc = load_scenario(name)
            assert judged_ladder_s(sc, resolve(v)) == tuple(sorted(sc.dt_ladder_s, reverse=True))


def test_the_floors_scale_with_the_precisions_epsilon():
    for n, amp in ((1, 1.0), (1000, 1.0), (20000, 50.0)):
        f64 = M.roundoff_floor(2.0, n, reference_error=0.0, amplification=amp)
        f32 = M.roundoff_floor(2.0, n, reference_error=0.0, amplification=amp,
                               eps=tol.MACHINE_EPSILON["float32"])
        assert f32 == pytest.approx(f64 * tol.MACHINE_EPSILON["float32"] / tol.MACHINE_EPSILON["float64"])
        # the reference's own (float64) error is added as measured, whatever the run's precision
        assert (M.roundoff_floor(2.0, n, reference_error=1e-9, eps=1e-7)
                == pytest.approx(1e-9 + 1e-7 * 2 * (n + n ** .5)))


@pytest.mark.parametrize("scheme", SCHEMES)
def test_a_float32_ladder_adds_coarser_rungs_within_the_limits(scheme, monkeypatch):
    """Every added rung is coarser than the scenario's, of half the steps of the last (T/Δt whole), turns the
    fastest motion by at most (p + 1) × 0.15 rad and keeps 16 steps; rungs are added until three are expected
    resolved or a limit stops them (checked here from the limits, not from the function's own arithmetic)."""
    v = register(monkeypatch, Float32Adapter("ok", scheme))
    p = nominal_order(resolve(v))
    extended = 0
    for name in catalog_names():
        sc = load_scenario(name)
        given = sorted(sc.dt_ladder_s, reverse=True)
        ladder = judged_ladder_s(sc, resolve(v))
        extra = ladder[:len(ladder) - len(given)]
        assert list(ladder[len(extra):]) == given and len(extra) <= tol.PRECISION_LADDER_MAX_EXTRA
        w = max(math.sqrt(characteristic_rate_sq(sc)), 1.0 / sc.duration_s)
        for coarse, fine in zip(extra, ladder[1:]):
            n = sc.duration_s / coarse
            assert abs(n - round(n)) < 1e-9 * n and round(n) == round(sc.duration_s / fine) // 2
            assert w * coarse <= (p + 1) * 0.15 + 1e-12 and n >= 16
        extended += bool(extra)
    assert extended >= (0 if p == 1 else 5)   # the higher orders need coarser rungs on most of the catalog


@pytest.mark.first   # one of the longest tests (tests/conftest.py)
def test_the_correct_float32_schemes_pass_the_sweeps_gates(tmp_path, monkeypatch):
    vs = [register(monkeypatch, Float32Adapter(f"ok_{s.split(':')[1]}", s)) for s in SCHEMES]
    summary = _sweep(tmp_path, QUICK_SCENARIOS, vs)
    assert _gate_failures(summary) == []
    recs = summary["convergence"]
    assert {r["engine"] for r in recs} == set(vs) and all(r["matches_expectation"] is not False for r in recs)
    # a float32 verdict says so, and which rungs it judged
    assert all("float32" in r["assessment"] for r in recs), [r["assessment"] for r in recs if "float32" not in
                                                              r["assessment"]]
    # every scheme shows its order somewhere (float32 leaves orders measurable, not only "at round-off")
    for v in vs:
        shown = [r for r in recs
                 if r["engine"] == v and r["mode"] == "free_running" and r["verdict"] == "converges"
                 and r["matches_expectation"] is True]
        assert shown, v


def test_the_same_float32_scheme_judged_with_float64_floors_fails(tmp_path, monkeypatch):
    """What the precision trait is for: the float32 expmap_gyro declared float64 is called non-convergent
    (its errors grow as Δt shrinks under float32 round-off: applied_torque's velocity)."""
    v = register(monkeypatch, Float32Adapter("as64", "reference:expmap_gyro", precision="float64"))
    summary = _sweep(tmp_path, ("applied_torque",), [v])
    bad = [r for r in summary["convergence"] if r["engine"] == v and r["matches_expectation"] is False]
    assert bad and _gate_failures(summary)


@pytest.mark.parametrize("name", F32_MUTANTS)
def test_a_float32_scheme_with_a_planted_bug_is_still_caught(name, tmp_path, monkeypatch):
    m = BY_NAME[name]
    v = register(monkeypatch, Float32Adapter(name, m.variant, m))
    summary = _sweep(tmp_path, m.exposed_by, [v])
    assert _gate_failures(summary), f"float32 {m.name} ({m.bug}) was not caught on {m.exposed_by}"


@pytest.mark.parametrize("name", ("gyroscopic_sign_flipped", "lever_arms_not_rotated"))
def test_a_planted_bug_is_still_caught_where_the_step_declares_a_rounding_factor(name, tmp_path, monkeypatch):
    """A declared rounding factor (Newton SemiImplicit's 2: its floors and one-step allowance at twice an
    ordinary step's rounding) widens round-off allowances only: a wrong equation's error and one-step defect
    are of a lower order in Δt, not a few roundings, and are still caught."""
    m = BY_NAME[name]
    v = register(monkeypatch, Float32Adapter(f"{name}_x2", m.variant, m, rounding_factor=2.0))
    assert machine_epsilon(resolve(v)) == 2.0 * tol.MACHINE_EPSILON["float32"]
    summary = _sweep(tmp_path, m.exposed_by, [v])
    assert _gate_failures(summary), f"float32 {m.name} ({m.bug}), factor 2, not caught on {m.exposed_by}"


@pytest.mark.slow
@pytest.mark.parametrize("scheme", SCHEMES)
def test_a_correct_float32_scheme_passes_on_the_whole_catalog(scheme, tmp_path, monkeypatch):
    v = register(monkeypatch, Float32Adapter("ok", scheme))
    assert _gate_failures(_sweep(tmp_path, catalog_names(), [v], load=load_scenario)) == []


@pytest.mark.parametrize("name", [*SCHEMES, *F32_MUTANTS])
def test_a_float32_schemes_runs_batched_are_its_runs_one_by_one(name, monkeypatch):
    """The sweeps above run each ladder as one batch (Float32Adapter.simulate_many); every run of it is the
    run alone, bit for bit: rungs of different lengths on the scheme's or the mutant's scenario."""
    from cross_checks.engines.base import RunRequest
    m = BY_NAME.get(name)
    adapter = Float32Adapter("batched", m.variant, m) if m else Float32Adapter("batched", name)
    sc = load_scenario(m.exposed_by[0] if m else "applied_torque")
    reqs = [RunRequest(sc, dt, min(sc.n_steps(dt), 30 + 17 * k)) for k, dt in enumerate(sc.dt_ladder_s)]
    for r, run in zip(reqs, adapter.simulate_many(adapter.scheme, reqs)):
        alone = adapter.simulate(r.scenario, adapter.scheme, r.dt_s, r.n_steps)
        assert run.message == alone.message and run.diverged_at_s == alone.diverged_at_s
        assert np.array_equal(run.t_s, alone.t_s) and np.array_equal(run.y, alone.y), (name, r.dt_s)


def test_the_float32_state_is_float32():
    y = np.array([0.1, 1.0 / 3.0, 2.0 ** 30 + 1.0])
    assert np.array_equal(to_float32(y).astype(np.float32).astype(np.float64), to_float32(y))
    assert not np.array_equal(to_float32(y), y)


# --- the fuzz judges float32 with the same model ------------------------------------------------------------

#: A torque-free tumble under gravity with a body-frame torque: every property of the fuzz has a claim here
#: (orders, one-step orders; energy is not conserved under the torque, so the spin-only case below has it).
FUZZ_TUMBLE = {"name": "f32_fuzz", "duration": 1.0, "dt": 0.01, "dt_ladder": [0.01, 0.005, 0.0025],
               "body": {"mass": 1.5, "inertia": [0.2, 0.35, 0.5]},
               "initial": {"angular_velocity": [0.4, 1.2, 0.3], "velocity": [1.0, 0.0, 2.0]},
               "forces": {"gravity": [0.0, 0.0, -9.81]}}


def test_the_fuzz_passes_a_correct_float32_scheme_and_catches_a_planted_bug(monkeypatch):
    """The fuzz's properties (orders, one-step orders, energy and momentum conservation) with float32 floors
    and allowances: a correct float32 scheme has no violation, where the same scheme judged as float64 and a
    float32 scheme with its gyroscopic sign flipped each have one."""
    from cross_checks.fuzz.pipeline import evaluate_specs
    ok = register(monkeypatch, Float32Adapter("fz_ok", "reference:expmap_gyro"))
    as64 = register(monkeypatch, Float32Adapter("fz_as64", "reference:expmap_gyro", precision="float64"))
    m = BY_NAME["gyroscopic_sign_flipped"]
    bad = register(monkeypatch, Float32Adapter("fz_bad", m.variant, m))
    (judged,) = evaluate_specs([FUZZ_TUMBLE], [resolve(v) for v in [ok, as64, bad]])
    by = {v: [x for x in judged.violations if v in x["variants"]] for v in (ok, as64, bad)}
    assert by[ok] == [], by[ok]
    assert judged.tally[ok]["conservation"][0] >= 1   # energy and momentum were judged, with float32 ε
    assert by[bad], "float32 gyroscopic sign flip not caught by the fuzz"
    assert by[as64], "float32 round-off judged with float64 allowances passed"


@pytest.mark.slow
def test_near_the_separatrix_float32_round_off_is_no_claim_and_a_wrong_step_fails(tmp_path, monkeypatch):
    """tumbling_box sits 2e-5 from the intermediate-axis separatrix: float32 rounding moves the body to a
    neighbouring motion, so a correct float32 RK4's errors do not shrink on any ladder. Its steps are the
    scenario's equations (one-step check), so no claim is made; the same RK4 with its gyroscopic sign flipped
    is not excused."""
    ok = register(monkeypatch, Float32Adapter("sep_ok", "reference:rk4"))
    m = BY_NAME["gyroscopic_sign_flipped_rk4"]
    bad = register(monkeypatch, Float32Adapter("sep_bad", m.variant, m))
    summary = run_sweep([load_scenario("tumbling_box")], [ok, bad], tmp_path / "out", jobs=1, use_cache=False,
                        progress=False, second_reference=False)
    recs = {(r["engine"], r["quantity"]): r for r in summary["convergence"]}
    rot = [recs[(ok, q)] for q in ("orientation", "angular_velocity")]
    assert all(r["matches_expectation"] is not False for r in rot), [r["assessment"] for r in rot]
    assert any("round-off grown by the motion" in r["assessment"] for r in rot)
    assert any(r["matches_expectation"] is False for (v, _), r in recs.items() if v == bad)

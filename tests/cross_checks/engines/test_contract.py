"""The engine contract, one suite for every engine installed here: rbcheck's own adapters, a Python engine
written against cross_checks.engines.world (examples/python_engine, docs/engines.md) and an engine file (the
worked C example). What each engine must do is the same: report its version and variants, start from the
scenario's state, give its batched runs exactly as its single ones, take the harness's forces (the weight
once, the decay before the step), report a blow-up as a divergence, and (where it has one) restart a step
from any state. An engine's own facts (conventions, defaults, pinned numbers) stay in its own test file."""
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from cross_checks import engines
from cross_checks.core import tolerances as core_tol
from cross_checks.engines import install, runtimes
from cross_checks.engines.base import EngineError, RunRequest
from cross_checks.engines.world import WorldEngine
from cross_checks.scenario import load_scenario
from tests.helpers import tolerances as tol
from tests.helpers.scenarios import with_initial

ROOT = Path(__file__).resolve().parents[3]
#: The engines with one declared order per variant that the suite runs (optional ones skip when absent).
BUILTIN = engines.BUILTIN_ENGINES
#: Scenarios with every force kind the loop treats apart: none, constant (a force, a torque), state-dependent,
#: decay.
SCENARIOS = ("tennis_racket", "projectile", "spring_pendulum", "velocity_decay", "applied_torque")
#: Engines whose every new run shape is compiled (JAX, Warp: seconds to a minute each): their first variant
#: only, so that the suite stays a few minutes on 2 cores; their other variants share that code path.
COMPILED = {"jaxsim", "brax", "mjx", "mujoco_warp", "genesis", "newton"}
#: World engines whose compiled batch (mjx: ``jax.vmap`` over the bodies, padded to a power of two) orders
#: a step's sums otherwise than a batch of one: their batched runs are their single ones to the round-off
#: allowed below (_same), not bit for bit (measured: the MJX adapter before its port onto the loop,
#: bit-identical to it, did the same).
VECTORISED = {"mjx", "jaxsim"}   # jaxsim: its world vmaps its bodies (one body alone: unvmapped)


def _python_engine():
    sys.path.insert(0, str(ROOT / "examples" / "python_engine"))
    try:
        from expmap_engine import ExpmapEngine
    finally:
        sys.path.pop(0)
    return ExpmapEngine()


ENGINES = [*BUILTIN, "python_example", "engine_file_example"]


@pytest.fixture(params=ENGINES)
def adapter(request, tmp_path_factory, monkeypatch):
    """The adapter of one engine, registered for the test; skipped where that engine cannot run here."""
    return _adapter(request.param, tmp_path_factory, monkeypatch)


@pytest.fixture(params=[pytest.param(e, marks=pytest.mark.slow) if e in COMPILED else e for e in ENGINES])
def costly_adapter(request, tmp_path_factory, monkeypatch):
    """:func:`adapter`, for the checks that compile new run shapes: a compiled engine's under -m slow (40-80 s
    each of compilation on 2 cores; its own test file covers its batched runs and one-step mode)."""
    return _adapter(request.param, tmp_path_factory, monkeypatch)


def _adapter(name, tmp_path_factory, monkeypatch):
    if name == "python_example":
        ad = _python_engine()
    elif name == "engine_file_example":
        from tests.helpers.byo import build_cbody, c_compiler
        if c_compiler() is None:
            pytest.skip("no C compiler for the worked example")
        from cross_checks.engines.external import load_engine_file
        ad = load_engine_file(build_cbody(tmp_path_factory.mktemp("cbody"))["good"])
    else:
        if name not in {v.split(":")[0] for v in engines.available_variants()}:
            pytest.skip(f"{name} is not available here")
        return engines.get_adapter(name)
    monkeypatch.setattr(engines, "_user", dict(engines._user))
    engines.register_adapter(ad, "tests/cross_checks/engines/test_contract.py")
    return ad


def _variants(adapter) -> list:
    return list(adapter.variants)[:1] if adapter.name in COMPILED else list(adapter.variants)


def _expressible(adapter, variant, names) -> list:
    return [n for n in names if not adapter.expressible(load_scenario(n), variant)]


def _eps(adapter, variant) -> float:
    traits = adapter.variants[variant].traits
    return core_tol.MACHINE_EPSILON[traits.precision if traits is not None else "float64"]


def _requests(names, steps):
    scs = [load_scenario(n) for n in names]
    return [RunRequest(sc, h, min(steps, sc.n_steps(h))) for sc in scs for h in (sc.dt_s, sc.dt_s / 2)]


def _same(a, b, eps: float) -> bool:
    """The same run: the same divergence and times, and the same states to the round-off of a batched
    computation (a compiled batch may order a step's sums differently): 16 ε per step of max(1, |y|). A loop
    that runs each body as if alone gives them bit for bit."""
    if isinstance(a, EngineError) or isinstance(b, EngineError):
        return type(a) is type(b) and str(a) == str(b)
    if a.diverged_at_s != b.diverged_at_s or a.message != b.message or not np.array_equal(a.t_s, b.t_s):
        return False
    allowed = tol.CONTRACT_ROUND_TRIP_EPS * eps * np.arange(len(a.y))[:, None] * np.maximum(1.0, np.abs(b.y))
    return a.y.shape == b.y.shape and bool(np.all(np.abs(a.y - b.y) <= allowed))


def _bit_for_bit(adapter) -> bool:
    """Whether the engine's batched runs are its single ones bit for bit: a world of several Δt
    (WorldEngine.mixed_steps: Brax's vmapped ladder) or a vmapped batch (MJX) is one compiled batch, whose
    sums may be ordered otherwise than a batch of one (the tolerance of _same only)."""
    return (((isinstance(adapter, WorldEngine) and not adapter.mixed_steps) or adapter.name == "reference")
            and adapter.name not in VECTORISED)


def test_it_declares_a_version_and_variants_with_orders(adapter):
    assert isinstance(adapter.version(), str) and adapter.version()
    assert adapter.variants and all(0 < v.order <= 20 for v in adapter.variants.values())


def test_a_run_starts_at_the_scenarios_state_and_records_every_step(adapter):
    for variant in _variants(adapter):
        for r in _requests(SCENARIOS[:2], 6):
            run = adapter.simulate(r.scenario, variant, r.dt_s, r.n_steps)
            assert run.diverged_at_s is None and run.y.shape == (r.n_steps + 1, 13)
            np.testing.assert_array_equal(run.t_s, r.dt_s * np.arange(r.n_steps + 1))
            # the state read back after it was set: a round trip through the engine's own layout
            y0 = r.scenario.problem.initial_packed()
            scale = np.maximum(1.0, np.abs(y0))
            allowed = tol.CONTRACT_ROUND_TRIP_EPS * _eps(adapter, variant)
            assert np.max(np.abs(run.y[0] - y0) / scale) <= allowed


def test_many_runs_in_one_call_are_its_single_runs(costly_adapter):
    adapter = costly_adapter
    for variant in _variants(adapter):
        requests = _requests(_expressible(adapter, variant, SCENARIOS), 12)
        got = adapter.simulate_many(variant, requests)
        assert len(got) == len(requests)
        for r, run in zip(requests, got):
            try:
                single = adapter.simulate(r.scenario, variant, r.dt_s, r.n_steps)
            except EngineError as exc:
                single = exc
            assert _same(run, single, _eps(adapter, variant)), (variant, r.scenario.name, r.dt_s)
            if _bit_for_bit(adapter):
                assert _same(run, single, 0.0), "the loop runs each body of a world as if alone"


def test_the_weight_is_applied_once_and_the_decay_before_the_step(adapter):
    """projectile: one step gains exactly g Δt in v (constant acceleration: any consistent scheme);
    velocity_decay (no force): one step scales the engine's own step without decay by the scenario's factor
    γ = e^{−x} at its own Δt — exactly for a single-stage step that takes the decay before it, and to the
    local error of an order-p scheme on v' = −k v (|R(−x) − e^{−x}| ≤ 2 x^{p+1}/(p+1)!, x = kΔt) for one that
    has it in its right-hand side. Against the engine's own undecayed step, not against γ v0: a step that
    couples the spin into v (jaxsim's inertial representation moves v by Δt² |ω × (ω × v)| = 2e-4 m/s here,
    decay or not: docs/engine_conventions.md) is the translation's first-order error, not the decay's. The
    decay left out or taken twice is off by x ≈ 1e-2 of |v|, 200 times the first-order allowance."""
    proj, decay = load_scenario("projectile"), load_scenario("velocity_decay")
    from cross_checks.scenario import parse_scenario
    text = (ROOT / "cross_checks" / "scenario" / "catalog" / "velocity_decay.toml").read_text()
    free = parse_scenario(text.replace("velocity_decay = 0.99\n", "velocity_decay = 1.0\n").replace(
        "angular_velocity_decay = 0.995", "angular_velocity_decay = 1.0"), "<velocity_decay without decay>")
    assert decay.problem.forces.has_decay and not free.problem.forces.has_decay
    for variant in _variants(adapter):
        eps = _eps(adapter, variant)
        run = adapter.simulate(proj, variant, proj.dt_s, 1)
        dv = run.y[1, 3:6] - run.y[0, 3:6]
        g_dt = np.asarray(proj.problem.forces.gravity_W) * proj.dt_s
        scale = max(1.0, np.max(np.abs(run.y[0])))
        assert np.max(np.abs(dv - g_dt)) <= tol.CONTRACT_ONE_STEP_EPS * eps * scale
        run = adapter.simulate(decay, variant, decay.dt_s, 1)
        v_free = adapter.simulate(free, variant, free.dt_s, 1).y[1, 3:6]
        g_v = decay.problem.forces.velocity_decay
        x, p = -math.log(g_v), math.floor(adapter.variants[variant].order)
        v0, v1 = run.y[0, 3:6], run.y[1, 3:6]
        allowed = (2 * x ** (p + 1) / math.factorial(p + 1)
                   + tol.CONTRACT_ONE_STEP_EPS * eps) * np.max(np.abs(v0))
        assert np.max(np.abs(v1 - g_v * v_free)) <= allowed, variant


#: Steps a blown-up run records before its divergence (below): the rows before it are kept.
ROWS_BEFORE = 4


def _blow_up():
    """tennis_racket moving fast in x (no force: x = x0 + k Δt v for any consistent scheme): below
    reference_sim.simulate.BLOWUP_LIMIT (1e8) for ROWS_BEFORE steps, beyond it at the next one."""
    sc = load_scenario("tennis_racket")
    v = 5e7
    return with_initial(sc, x_W=[1e8 - (ROWS_BEFORE - 0.5) * v * sc.dt_s, 0.0, 0.0], v_W=[v, 0.0, 0.0])


def _is_the_blow_up(adapter, run, dt_s) -> bool:
    # an engine file's run says that the engine wrote the state (engines/external.py), an adapter's does not
    by = ", written by the engine" if type(adapter).__module__ == "cross_checks.engines.external" else ""
    return (run.diverged_at_s == pytest.approx(ROWS_BEFORE * dt_s)
            and run.message == f"diverged at t = {run.diverged_at_s:.6g} s (state beyond 1e+08{by})"
            and len(run.y) == len(run.t_s) == ROWS_BEFORE and bool(np.all(np.abs(run.y) <= 1e8)))


def test_a_blow_up_is_a_divergence_at_its_step_with_the_rows_before_it(adapter):
    sc = _blow_up()
    for variant in _variants(adapter):
        run = adapter.simulate(sc, variant, sc.dt_s, 2 * ROWS_BEFORE)
        assert _is_the_blow_up(adapter, run, sc.dt_s), (variant, run.diverged_at_s, run.message, len(run.y))
        np.testing.assert_array_equal(run.t_s, sc.dt_s * np.arange(ROWS_BEFORE))


def test_a_blow_up_among_many_runs_leaves_the_others_alone(costly_adapter):
    adapter, sc = costly_adapter, _blow_up()
    calm = load_scenario("tennis_racket")
    for variant in _variants(adapter):
        blown, other = adapter.simulate_many(variant, [RunRequest(sc, sc.dt_s, 2 * ROWS_BEFORE),
                                                       RunRequest(calm, sc.dt_s, 2 * ROWS_BEFORE)])
        assert _is_the_blow_up(adapter, blown, sc.dt_s), variant
        assert other.diverged_at_s is None
        alone = adapter.simulate(calm, variant, sc.dt_s, 2 * ROWS_BEFORE)
        assert _same(other, alone, 0.0 if _bit_for_bit(adapter) else _eps(adapter, variant)), variant


def test_one_step_restarts_from_any_state(costly_adapter):
    adapter = costly_adapter
    if not adapter.has_one_step:
        pytest.skip(f"{adapter.name} has no one-step mode")
    for variant in _variants(adapter):
        sc = load_scenario(_expressible(adapter, variant, ["spring_pendulum", "tennis_racket"])[0])
        run = adapter.simulate(sc, variant, sc.dt_s, 8)
        y1 = adapter.one_step(sc, variant, sc.dt_s, run.y[:-1])
        assert y1.shape == run.y[1:].shape
        scale = np.maximum(1.0, np.abs(run.y[1:]))
        # from the recorded states the engine's steps again: the run's next states, to the round-off of the
        # state's round trip through the engine's layout, amplified by one step (an implicit step's solve
        # stops at its own tolerance: tol.CONTRACT_RESTART_EPS)
        assert np.max(np.abs(y1 - run.y[1:]) / scale) <= tol.CONTRACT_RESTART_EPS * _eps(adapter, variant)


def test_a_body_torque_the_engine_takes_itself_moves_the_body_as_the_harness_does(adapter, monkeypatch):
    """An engine that declares ``takes_body_torque`` (MuJoCo: qfrc_applied on the free joint's body-axes
    DOFs) moves applied_torque's body (a body-frame torque beside an off-COM world force) as the same engine
    driven by the harness alone (its torque R(q)τ_B at the start of each step, or each stage): the runs at
    two Δt and one step from the run's states agree to the round-off of the torque's other rotation
    (the tests' SAME_SCHEME_REL; measured on MuJoCo: ≤ 1.6e-15 relative)."""
    if not getattr(adapter, "takes_body_torque", False):
        pytest.skip(f"{adapter.name} takes no body torque itself")
    sc = load_scenario("applied_torque")
    own = {v: [adapter.simulate(sc, v, h, 200).y for h in (sc.dt_s * 4, sc.dt_s)] for v in adapter.variants}
    ones = {v: adapter.one_step(sc, v, sc.dt_s, own[v][1][::20]) for v in adapter.variants}
    monkeypatch.setattr(type(adapter), "takes_body_torque", False)
    for v in adapter.variants:
        for y, h in zip(own[v], (sc.dt_s * 4, sc.dt_s)):
            want = adapter.simulate(sc, v, h, 200).y
            assert np.max(np.abs(y - want) / (np.abs(want).max(axis=0) + 1.0)) <= tol.SAME_SCHEME_REL, (v, h)
        want = adapter.one_step(sc, v, sc.dt_s, own[v][1][::20])
        assert np.max(np.abs(ones[v] - want) / (np.abs(want) + 1.0)) <= tol.SAME_SCHEME_REL, v


def test_a_run_through_the_registry_records_the_engines_own_time_within_its_wall_time(adapter):
    variant = next(iter(adapter.variants))
    sc = load_scenario("spring_pendulum")
    traj = engines.run_variants(sc, f"{adapter.name}:{variant}", [sc.dt_s], duration_s=0.05)[0]
    meta = traj.meta
    if isinstance(adapter, WorldEngine) or adapter.name == "reference":
        assert 0.0 < meta["engine_s"] <= meta["wall_s"]
    else:   # an adapter that owns its loop cannot tell the engine's time from its own
        assert math.isnan(meta["engine_s"]) and meta["wall_s"] > 0


def test_an_engine_that_is_missing_says_how_to_install_it(adapter):
    if not isinstance(adapter, WorldEngine) or not adapter.extra:
        pytest.skip(f"{adapter.name} is a required engine or not a world engine")
    if type(adapter).version not in (WorldEngine.version, runtimes.JaxEngine.version):
        pytest.skip(f"{adapter.name} reads its version from its module (its absence: test_optional.py)")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(install, "installed_version", lambda dist: None)
        mp.setattr(install, "optional_import",
                   lambda name, **kw: (None, ImportError(f"No module named {name!r}")))
        if adapter.imported:   # the adapter module imported its engine at its own import: that import failed
            module = sys.modules[type(adapter).__module__]
            mp.setattr(module, adapter.imported, None)
            mp.setattr(module, "_IMPORT_ERROR", ImportError(f"No module named {adapter.imported!r}"))
        with pytest.raises(install.EngineNotInstalled, match=rf"\[{adapter.extra}\]"):
            adapter.version()

"""The World API's worked example (docs/engines.md, examples/python_engine/expmap_engine.py): the page shows
the file as it is, and the engine, registered as any user engine, is swept beside MuJoCo with every verdict
as expected and its runs equal to the reference's scheme it implements (reference:expmap_gyro) to round-off.
The engine contract itself is tests/cross_checks/engines/test_contract.py's (it runs this engine too)."""
import sys
from pathlib import Path

import numpy as np

from cross_checks import engines
from cross_checks.scenario import load_scenario
from tests.helpers import tolerances as tol

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE = ROOT / "examples" / "python_engine" / "expmap_engine.py"


def _engine():
    sys.path.insert(0, str(EXAMPLE.parent))
    try:
        from expmap_engine import ExpmapEngine
    finally:
        sys.path.pop(0)
    return ExpmapEngine()


def test_the_page_shows_the_example_as_it_is_and_it_is_short():
    text = EXAMPLE.read_text(encoding="utf-8")
    assert text in (ROOT / "docs" / "engines.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 80


def test_the_example_is_swept_beside_mujoco_with_every_verdict_as_expected(tmp_path, monkeypatch):
    from cross_checks.sweep import run_sweep
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(engines, "_user", dict(engines._user))
    engines.register_adapter(_engine(), "examples/python_engine/expmap_engine.py")
    scs = [load_scenario(n) for n in ("applied_torque", "projectile")]
    summary = run_sweep(scs, ["expmap:euler", "mujoco:euler"], tmp_path / "r", jobs=1, second_reference=False)
    mine = [r for r in summary["convergence"] if r["engine"] == "expmap:euler"]
    assert mine and all(r["matches_expectation"] for r in mine)
    for sc in scs:   # the scheme it implements, to the round-off of a differently ordered computation
        a = engines.run_variant(sc, "expmap:euler").y
        b = engines.run_variant(sc, "reference:expmap_gyro").y
        assert np.max(np.abs(a - b)) <= tol.EXAMPLE_ENGINE_VS_ITS_SCHEME * max(1.0, np.max(np.abs(b)))


def test_a_host_rows_world_keeps_a_copy_of_the_packed_rows_it_is_set_to():
    """world.HostRowsWorld (Brax's world's base): the rows live on the host between compiled rollouts, so a
    caller changing its array afterwards must not move the bodies; ``ends`` are the requests' steps."""
    from types import SimpleNamespace

    from cross_checks.engines.world import HostRowsWorld
    w = HostRowsWorld([SimpleNamespace(n_steps=4), SimpleNamespace(n_steps=9)])
    assert w.read().shape == (2, 13) and w.ends == [4, 9] and w.host_s == 0.0 and w.rollout_takes_all_forces
    y = np.arange(26, dtype=float).reshape(2, 13)
    w.set_state(y)
    y[:] = -1.0
    assert np.array_equal(w.read(), np.arange(26, dtype=float).reshape(2, 13))


def test_blown_up_names_the_live_bodies_whose_row_is_bad_as_the_loop_judges_them():
    """world.blown_up (what PhysX's, DART's and Rapier's worlds stop once read) gives, for rows as plain
    floats and as an array alike, exactly the live bodies whose row reference_sim.simulate.bad_rows calls bad:
    non-finite, or a component beyond BLOWUP_LIMIT (either sign); none in the common case."""
    from cross_checks.engines.world import blown_up
    from reference_sim.simulate import BLOWUP_LIMIT, bad_rows
    rng = np.random.default_rng(7)
    rows = rng.normal(size=(9, 13)) * 10.0
    assert blown_up(rows, [True] * 9) == [] and blown_up(rows.tolist(), [True] * 9) == []
    rows[1, 3], rows[2, 12], rows[4, 0], rows[5, 7] = np.nan, np.inf, -2.0 * BLOWUP_LIMIT, BLOWUP_LIMIT
    rows[6, 9] = np.nextafter(BLOWUP_LIMIT, np.inf)
    live = [True] * 9
    live[4] = False
    want = [k for k in range(9) if live[k] and bad_rows(rows[k][None])[0]]
    assert want == [1, 2, 6]
    assert blown_up(rows, live) == want and blown_up(rows.tolist(), live) == want
    assert blown_up(rows, np.array(live)) == want and blown_up(rows.tolist(), np.array(live)) == want


def test_plain_float_reads_become_the_rows_numpy_makes_of_them():
    """World.rows of a world whose reads are B rows of plain floats (``float_reads``: DART's, PyBullet's,
    PhysX's few bodies) flattens a chunk in one pass into the array NumPy's conversion gives, bit for bit."""
    from cross_checks.engines.world import World

    class Floats(World):
        float_reads = True
    reads = [np.random.default_rng(k).normal(size=(3, 12)).tolist() for k in range(5)]
    reads[2][1] = tuple(reads[2][1])   # PyBullet reads tuples
    got = Floats().rows(reads)
    assert got.shape == (5, 3, 12) and np.array_equal(got, np.asarray(reads, dtype=float))
    assert np.array_equal(World().rows(reads), got)


def test_body_specs_computes_each_distinct_bodys_spec_once_in_the_requests_order():
    from types import SimpleNamespace

    from cross_checks.engines.world import body_specs
    a, b = object(), object()
    reqs = [SimpleNamespace(scenario=SimpleNamespace(problem=SimpleNamespace(body=x)))
            for x in (a, b, a, a, b)]
    calls = []
    specs = body_specs(reqs, lambda body: calls.append(body) or ("spec", id(body)))
    assert calls == [a, b] and specs == [("spec", id(x)) for x in (a, b, a, a, b)]


def test_a_body_entry_carries_the_com_and_each_welded_parts_spec_as_the_worlds_take_them():
    """world.body_entry (DART's, Drake's, PyBullet's body; rbcheck repro writes it): the body's spec; with
    the origin off the COM also that COM; with welded parts also each part's spec (of a body of its mass and
    inertia) and COM, as plain floats."""
    from types import SimpleNamespace

    from cross_checks.engines.world import body_entry
    from reference_sim.body import BodyPart, RigidBody

    def spec_of(body):
        return float(body.mass_kg), np.asarray(body.inertia_B, dtype=float), None
    body = RigidBody(3.0, np.diag([1.0, 2.0, 2.5]))
    plain = SimpleNamespace(problem=SimpleNamespace(body=body))
    assert body_entry(plain, spec_of)[:2] == (3.0, body.inertia_B) and len(body_entry(plain, spec_of)) == 3
    com = SimpleNamespace(problem=plain.problem, body_com_B_m=np.array([0.1, -0.2, 0.3]))
    entry = body_entry(com, spec_of)
    assert len(entry) == 4 and entry[3] == [0.1, -0.2, 0.3] and all(type(v) is float for v in entry[3])
    parts = (BodyPart(1.0, [0.5, 0.0, 0.0], np.diag([0.1, 0.2, 0.25])),
             BodyPart(2.0, [-0.25, 0.0, 0.0], [[0.3, 0.01, 0.0], [0.01, 0.4, 0.0], [0.0, 0.0, 0.5]]))
    welded = SimpleNamespace(problem=plain.problem, body_com_B_m=np.zeros(3), body_parts=parts)
    entry = body_entry(welded, spec_of)
    assert len(entry) == 5 and len(entry[4]) == 2
    for (m, inertia, frame, c), part in zip(entry[4], parts):
        assert m == part.mass_kg and np.array_equal(inertia, part.inertia_B) and frame is None
        assert c == part.com_B_m.tolist()


def test_an_engine_builds_its_declared_world_once_installed_and_names_what_is_missing(monkeypatch):
    """WorldEngine.build makes the declared ``world`` after the install check; where the adapter module
    imported its engine at its own import (``imported``: the global holding it, None there when it failed,
    ``_IMPORT_ERROR`` saying why) the check reads those, naming the distribution and the extra that installs
    it; an engine with neither a world nor a build of its own says so."""
    import pytest

    from cross_checks.engines import install
    from cross_checks.engines.world import WorldEngine

    class Made:
        def __init__(self, requests, variant, dt_s):
            self.args = (requests, variant, dt_s)

    class Declared(WorldEngine):
        name, variants, world, distribution, extra = "declared", {}, Made, "numpy", "declared"
        imported = "_ENGINE_MODULE"
    here = sys.modules[__name__]
    monkeypatch.setattr(here, "_ENGINE_MODULE", np, raising=False)
    monkeypatch.setattr(here, "_IMPORT_ERROR", None, raising=False)
    assert Declared().build(["r"], "v", 0.5).args == (["r"], "v", 0.5)
    monkeypatch.setattr(here, "_ENGINE_MODULE", None)
    monkeypatch.setattr(here, "_IMPORT_ERROR", ImportError("No module named 'x'"))
    with pytest.raises(ImportError, match=r"^numpy \S+ is installed but cannot be imported: ImportError: "
                                          r"No module named 'x'$") as e:
        Declared().build(["r"], "v", 0.5)
    assert not isinstance(e.value, install.EngineNotInstalled)
    monkeypatch.setattr(install, "installed_version", lambda dist: None)
    with pytest.raises(install.EngineNotInstalled, match=r"^numpy is not installed \(pip install "
                                                         r"'rbcheck\[declared\]'\)$"):
        Declared().version()

    class Nothing(WorldEngine):
        name, variants = "nothing", {}
    with pytest.raises(TypeError, match="Nothing declares no world and does not define build"):
        Nothing().build([], "v", 0.1)


def test_a_principal_spec_keeps_a_diagonal_tensors_axes_and_rotates_a_full_one_into_its_principal_frame():
    """world.principal_spec (PyBullet's, Rapier's, Drake's body): a diagonal tensor as its diagonal in the
    given order (principal_axes would sort it), with the frame the engine gives no rotation; a full tensor as
    its principal moments and frame, R_BP diag(moments) R_BPᵀ = I_B to round-off, q_BP (w, x, y, z) by
    default or R_BP itself."""
    from cross_checks.engines.world import principal_spec
    from reference_sim.body import RigidBody
    from reference_sim.quaternion import matrix_from_quat
    diag = RigidBody(2.0, np.diag([3.0, 1.0, 2.5]))
    m, moments, frame = principal_spec(diag)
    assert m == 2.0 and type(m) is float and moments.tolist() == [3.0, 1.0, 2.5] and frame is None
    identity = np.array([1.0, 0.0, 0.0, 0.0])
    assert principal_spec(diag, diagonal=identity)[2] is identity
    full = RigidBody(1.5, [[2.0, 0.1, 0.05], [0.1, 3.0, -0.2], [0.05, -0.2, 4.0]])
    m, moments, q_BP = principal_spec(full)
    R_BP = full.principal_axes()[1]
    assert m == 1.5 and np.array_equal(moments, full.principal_axes()[0])
    assert np.array_equal(principal_spec(full, frame=lambda R: R)[2], R_BP)
    assert np.allclose(matrix_from_quat(q_BP), R_BP, rtol=0.0, atol=tol.PRINCIPAL_FRAME_ROUND_TRIP)
    back = R_BP @ np.diag(moments) @ R_BP.T
    assert np.allclose(back, full.inertia_B, rtol=0.0, atol=tol.PRINCIPAL_FRAME_ROUND_TRIP * 4.0)


def test_an_adapter_module_exports_one_instances_version_and_runs():
    """WorldEngine.exported: one instance and its bound methods, what each adapter module exports."""
    from cross_checks.engines.world import WorldEngine

    class Declared(WorldEngine):
        name, variants, distribution = "declared", {}, "numpy"
    engine, version, simulate, simulate_many, one_step = Declared.exported()
    assert type(engine) is Declared and version() == engine.version()
    for f, name in ((simulate, "simulate"), (simulate_many, "simulate_many"), (one_step, "one_step")):
        assert f.__self__ is engine and f.__func__ is getattr(WorldEngine, name)



def test_many_bodies_is_one_number_for_the_harness_and_the_worlds(monkeypatch):
    """Above world.MANY_BODIES bodies the harness evaluates the forces in one compiled call, and the worlds
    that take them as arrays switch at the same count, read from that one constant (Rapier's serialisation
    reads, PhysX's array forces)."""
    import pytest

    from cross_checks.engines import world
    from cross_checks.engines.base import RunRequest
    from cross_checks.engines.loop import Harness
    sc = load_scenario("spring_pendulum")
    assert Harness([sc] * world.MANY_BODIES, 0.01, True).rows is None
    assert Harness([sc] * (world.MANY_BODIES + 1), 0.01, True).rows is not None
    monkeypatch.setattr(world, "MANY_BODIES", 1)
    two = [RunRequest(sc, 0.01, 3)] * 2
    pytest.importorskip("rapier3d")
    pytest.importorskip("sapien")
    from cross_checks.engines import physx_engine, rapier_engine
    assert rapier_engine.RapierWorld(two, "symplectic_euler", 0.01).layout is not None
    assert rapier_engine.RapierWorld(two[:1], "symplectic_euler", 0.01).layout is None
    assert physx_engine.PhysxWorld(two, "tgs", 0.01).many
    assert not physx_engine.PhysxWorld(two[:1], "tgs", 0.01).many


def test_an_engine_whose_runs_may_differ_in_length_groups_them_by_step_and_float32_gravity():
    """``any_length`` (Rapier, PhysX): one world per Δt and float32 gravity, whatever the runs' lengths (a
    gravity that float32 does not tell apart is the same world's); otherwise one per Δt and length."""
    from cross_checks.engines.base import RunRequest
    from cross_checks.engines.world import WorldEngine
    from tests.helpers.scenarios import scenario_from_parts
    g = [scenario_from_parts(forces=f"gravity = [0.0, 0.0, {z!r}]")
         for z in (-9.81, -9.81 * (1 + 1e-12), -9.0)]
    reqs = [RunRequest(g[0], 0.01, 10), RunRequest(g[1], 0.01, 20), RunRequest(g[2], 0.01, 10),
            RunRequest(g[0], 0.02, 10)]
    keys = [type("Any", (WorldEngine,), {"any_length": True})().group_key(r) for r in reqs]
    assert keys[0] == keys[1] and len(set(keys)) == 3
    by_length = [WorldEngine().group_key(r) for r in reqs]
    assert by_length[0] == by_length[2] != by_length[1] and len(set(by_length)) == 3

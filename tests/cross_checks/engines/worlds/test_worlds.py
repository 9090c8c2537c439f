"""cross_checks/engines/worlds/: each engine's world imports only NumPy and its engine (so that `rbcheck
repro` can embed it in a script that runs without rbcheck), and it IS the adapter's world: its steps, driven
as a reproducer drives them, equal the adapter's to the bit."""
import ast
import importlib
from pathlib import Path

import numpy as np
import pytest

from cross_checks.engines.base import RunRequest
from cross_checks.scenario import load_scenario

WORLDS = Path(__file__).resolve().parents[4] / "cross_checks" / "engines" / "worlds"
#: the modules each world may import besides numpy and the standard library ("." : a sibling world, which a
#: reproducer embeds above it)
ENGINE_IMPORT = {"mujoco": {"mujoco", "."}, "rapier": {"rapier3d"}, "pybullet": {"pybullet"},
                 "mjx": {"jax", "mujoco", "."}, "brax": {"jax", "brax", "mujoco"},
                 "physx": {"sapien"}, "dart": {"dartpy", "."}, "drake": {"pydrake", "."}, "com": set(),
                 "mujoco_warp": {"mujoco", "mujoco_warp", "warp", "."}, "jaxsim": {"jax", "jaxsim"},
                 "newton": {"warp", "newton", "mujoco"}, "genesis": {"genesis"}}
STDLIB = {"math", "dataclasses", "warnings"}


def _imports(path: Path) -> set:
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            out.add("." if node.level else (node.module or "").split(".")[0])
    return out


@pytest.mark.parametrize("engine", sorted(ENGINE_IMPORT))
def test_a_world_imports_only_numpy_and_its_engine(engine):
    got = _imports(WORLDS / f"{engine}.py")
    assert got <= {"numpy", *ENGINE_IMPORT[engine], *STDLIB}, got


def test_every_world_module_is_checked():
    assert {p.stem for p in WORLDS.glob("*.py")} - {"__init__"} == set(ENGINE_IMPORT)


# variant, scenario (a full-tensor tumble for the engines whose boundary rotates into the principal frame)
CASES = [("mujoco", "rk4", "tennis_racket"), ("mujoco", "euler", "tumbling_box"),
         ("rapier", "symplectic_euler", "tennis_racket"), ("pybullet", "maximal", "tumbling_box"),
         ("pybullet", "multibody", "projectile"), ("physx", "tgs", "tumbling_box"),
         ("physx", "pgs", "projectile"), ("dart", "semi_implicit_euler", "tumbling_box"),
         ("drake", "runge_kutta3", "tennis_racket"), ("drake", "semi_explicit_euler", "projectile"),
         ("drake", "implicit_euler", "tumbling_box"),
         ("mujoco_warp", "rk4", "tennis_racket"), ("mujoco_warp", "euler", "projectile"),
         ("newton", "semi_implicit", "tumbling_box"), ("newton", "featherstone", "tennis_racket"),
         ("newton", "mujoco_cpu", "projectile"), ("genesis", "euler", "tumbling_box"),
         ("genesis", "implicitfast", "projectile"),
         pytest.param("mjx", "rk4", "tennis_racket", marks=pytest.mark.slow),   # ~1 min each: JAX compiles
         pytest.param("brax", "spring", "tennis_racket", marks=pytest.mark.slow),
         pytest.param("brax", "generalized", "projectile", marks=pytest.mark.slow),
         pytest.param("jaxsim", "rk4", "tennis_racket", marks=pytest.mark.slow),
         pytest.param("jaxsim", "semi_implicit_euler", "projectile", marks=pytest.mark.slow)]


@pytest.mark.parametrize("engine,variant,name", CASES)
def test_the_reproducers_run_of_the_world_is_the_adapters_bit_for_bit(engine, variant, name):
    pytest.importorskip({"rapier": "rapier3d", "mjx": "mujoco.mjx", "physx": "sapien",
                         "dart": "dartpy", "drake": "pydrake",
                         "mujoco_warp": "mujoco_warp"}.get(engine, engine))
    from cross_checks.engines import get_adapter
    from cross_checks.engines.loop import Harness
    from cross_checks.sweep.repro import ENGINES, _source
    from cross_checks.sweep.repro_text import compact
    adapter_mod = importlib.import_module(ENGINES[engine][2])
    spec_mod = importlib.import_module(ENGINES[engine][3])
    getattr(adapter_mod, "start_for_repro", lambda: None)()   # Warp: started as the adapter starts it
    # what a reproducer embeds: the world and the measurement compacted (repro_text), not the modules
    script = {"__name__": "repro"}
    code = compact([_source(m) for m in [*ENGINES[engine][1], "cross_checks.sweep.repro_measure"]],
                   "def reached():\n    return run, world\n")
    exec(compile(code, f"<{engine} reproducer>", "exec"), script)   # noqa: S102
    sc = load_scenario(name)
    dt, n = sc.dt_ladder_s[0], 200
    f, tau = Harness([sc], dt, adapter_mod._ENGINE.applies_gravity).wrench(sc.problem.initial_packed()[None])
    s = {"BODIES": [spec_mod.body_spec(sc.problem.body)], "GRAVITY_W": sc.problem.forces.gravity_W,
         "VARIANT": variant, "Y0": sc.problem.initial_packed(), "F_W": f[0], "TAU_W": tau[0]}
    mine = script["run"](script["world"], s, dt, n)
    theirs = get_adapter(engine).simulate_many(variant, [RunRequest(sc, dt, n)])[0].y
    if adapter_mod._ENGINE.sign_continuity:   # the loop picks each quaternion's sign; the script need not
        mine[:, 6:10] *= np.sign(np.sum(mine[:, 6:10] * theirs[:, 6:10], axis=-1))[:, None]
    np.testing.assert_array_equal(mine[1:], theirs[1:])


def test_a_step_drake_refuses_reads_as_nan_in_a_reproducer_and_as_the_last_state_in_the_adapter():
    pytest.importorskip("pydrake")
    from cross_checks.engines import drake_engine as de
    from cross_checks.engines.worlds import drake as dkw
    sc = load_scenario("tennis_racket")
    y0 = sc.problem.initial_packed()[None]
    nan_force = np.array([[np.nan, 0.0, 0.0]])   # Drake refuses it: "Detected NaN in applied ... port"
    w = dkw.world([de.body_spec(sc.problem.body)], sc.problem.forces.gravity_W, "runge_kutta3", 0.01)
    w.set_state(y0)
    w.apply(nan_force, np.zeros((1, 3)))
    w.step()
    assert np.isnan(w.packed(w.read())).all()             # a script's run: diverged at that step
    assert w.warnings and w.warnings[0][:2] == (0, 1) and "NaN" in w.warnings[0][2]
    w.step()                                              # not stepped again
    assert len(w.warnings) == 1
    a = de.DrakeWorld([RunRequest(sc, 0.01, 2)], "runge_kutta3", 0.01)
    a.set_state(y0)
    start = a.read().copy()
    a.apply(nan_force, np.zeros((1, 3)))
    a.step()
    np.testing.assert_array_equal(a.read(), start)   # kept: the loop ends the run at the warning
    assert a.warnings[0][:2] == (0, 1) and "NaN" in a.warnings[0][2]


def _compacted(engine, tail):
    """The namespace of what a reproducer of ``engine`` embeds (its worlds and the measurement, compacted),
    ``tail`` reaching what the test calls."""
    from cross_checks.sweep.repro import ENGINES, _source
    from cross_checks.sweep.repro_text import compact
    script = {"__name__": "repro"}
    code = compact([_source(m) for m in [*ENGINES[engine][1], "cross_checks.sweep.repro_measure"]], tail)
    exec(compile(code, f"<{engine} reproducer>", "exec"), script)   # noqa: S102
    return script


def _form_scenario(name, kind):
    """Catalog scenario ``name`` under the sweep's ``com_offset`` or ``welded_split`` transform."""
    from cross_checks.scenario.transforms import apply, default_transforms
    sc = name if not isinstance(name, str) else load_scenario(name)
    return apply(next(t for t in default_transforms() if t.kind == kind), sc)


EXTRA = Path(__file__).resolve().parents[4] / "benchmarks" / "bit_identity"
#: (engine, variant, scenario, form): a body off its COM or of welded parts, in each engine that builds one
FORM_CASES = [("mujoco", "rk4", "tennis_racket", "com_offset"),
              ("mujoco", "euler", "tumbling_box", "welded_split"),
              ("mujoco", "implicit", EXTRA / "welded_push.toml", ""),
              ("drake", "implicit_euler", "tumbling_box", "com_offset"),
              ("drake", "runge_kutta3", "tennis_racket", "welded_split"),
              ("drake", "semi_explicit_euler", EXTRA / "com_push.toml", ""),
              ("dart", "semi_implicit_euler", "tennis_racket", "com_offset"),
              ("dart", "semi_implicit_euler", EXTRA / "welded_push.toml", ""),
              ("pybullet", "maximal", "tumbling_box", "com_offset"),
              ("pybullet", "multibody", EXTRA / "com_push.toml", "")]
_MODULE = {"dart": "dartpy", "drake": "pydrake"}


def _form_case(engine, name, kind):
    pytest.importorskip(_MODULE.get(engine, engine))
    return _form_scenario(name, kind) if kind else load_scenario(str(name))


@pytest.mark.parametrize("engine,variant,name,kind", FORM_CASES)
def test_a_reproducers_form_world_runs_a_body_off_its_com_or_of_parts_as_the_adapter_bit_for_bit(
        engine, variant, name, kind):
    """The invariance claims com_offset and welded_split: the script's ``form_world`` of the adapter's
    ``body_entry`` (the state converted between the COM and the body origin, worlds/com.py; the forces
    shared among the parts), run as a reproducer runs it, is the adapter's run to the bit."""
    sc = _form_case(engine, name, kind)
    from cross_checks.engines import get_adapter
    from cross_checks.engines.loop import Harness
    from cross_checks.sweep.repro import ENGINES
    adapter_mod, spec_mod = (importlib.import_module(m) for m in ENGINES[engine][2:4])
    script = _compacted(engine, "def reached():\n    return run, form_world\n")
    dt, n = sc.dt_ladder_s[0], 200
    f, tau = Harness([sc], dt, adapter_mod._ENGINE.applies_gravity).wrench(sc.problem.initial_packed()[None])
    s = {"BODIES": [spec_mod.body_entry(sc)], "GRAVITY_W": sc.problem.forces.gravity_W, "VARIANT": variant,
         "Y0": sc.problem.initial_packed(), "F_W": f[0], "TAU_W": tau[0]}
    assert len(s["BODIES"][0]) > 3   # the form is in the body's entry
    mine = script["run"](script["form_world"], s, dt, n)
    theirs = get_adapter(engine).simulate_many(variant, [RunRequest(sc, dt, n)])[0].y
    if adapter_mod._ENGINE.sign_continuity:
        mine[:, 6:10] *= np.sign(np.sum(mine[:, 6:10] * theirs[:, 6:10], axis=-1))[:, None]
    np.testing.assert_array_equal(mine[1:], theirs[1:])


@pytest.mark.parametrize("engine,variant,name,kind", [c for c in FORM_CASES if not c[3]])
def test_a_form_worlds_force_and_torque_act_as_the_adapters_world_bit_for_bit(engine, variant, name, kind):
    """A world force at the COM (shared among welded parts in MuJoCo, moved to the body origin in Drake and
    DART) and a world torque, the same arrays given to the script's form_world and to the adapter's world:
    the same states, bit for bit (with the forces a scenario holds, the weight taken off, the force is
    often zero)."""
    sc = _form_case(engine, name, kind)
    from cross_checks.engines import get_adapter
    from cross_checks.sweep.repro import ENGINES
    spec_mod = importlib.import_module(ENGINES[engine][3])
    script = _compacted(engine, "def reached():\n    return run, form_world\n")
    dt, n = sc.dt_ladder_s[0], 100
    y0 = sc.problem.initial_packed()[None]
    f, tau = np.array([[0.7, -1.3, 2.1]]), np.array([[0.05, 0.11, -0.07]])
    ours = script["form_world"]([spec_mod.body_entry(sc)], sc.problem.forces.gravity_W, variant, dt)
    theirs = get_adapter(engine).build([RunRequest(sc, dt, n)], variant, dt)
    try:
        rows = []
        for w in (ours, theirs):
            w.set_state(y0)
            out = [w.packed(np.asarray(w.read(), dtype=float)[None])[0, 0]]
            for _ in range(n):
                w.apply(f, tau)
                w.step()
                out.append(w.packed(np.asarray(w.read(), dtype=float)[None])[0, 0])
            rows.append(np.array(out))
    finally:
        getattr(theirs, "close", lambda: None)()
    assert np.all(np.isfinite(rows[0])) and not np.allclose(rows[0][-1, 3:6], y0[0, 3:6])   # it moved
    np.testing.assert_array_equal(rows[0], rows[1])

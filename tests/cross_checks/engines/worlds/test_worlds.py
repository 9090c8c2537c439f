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
ENGINE_IMPORT = {"mujoco": {"mujoco"}, "rapier": {"rapier3d"}, "pybullet": {"pybullet"},
                 "mjx": {"jax", "mujoco", "."}, "brax": {"jax", "brax", "mujoco"},
                 "physx": {"sapien"}, "dart": {"dartpy"}, "drake": {"pydrake"},
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


def test_jaxsims_adapter_declares_its_worlds_chunk_integrators_and_model_name():
    pytest.importorskip("jaxsim")
    from cross_checks.engines import jaxsim_engine as je
    jsw = je._world()   # the adapter holds them without importing JAX; the world's loop is what runs
    assert (je.CHUNK, je.INTEGRATORS, je.MODEL_NAME) == (jsw.CHUNK, jsw.INTEGRATORS, jsw.MODEL_NAME)


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

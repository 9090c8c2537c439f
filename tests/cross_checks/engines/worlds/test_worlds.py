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
                 "mjx": {"jax", "mujoco", "."}, "brax": {"jax", "brax"},
                 "physx": {"sapien"}, "dart": {"dartpy"}, "newton": {"warp", "newton", "mujoco"},
                 "genesis": {"genesis"}}
STDLIB = {"math", "warnings"}


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
         ("newton", "semi_implicit", "tumbling_box"), ("newton", "featherstone", "tennis_racket"),
         ("newton", "mujoco_cpu", "projectile"), ("genesis", "euler", "tumbling_box"),
         ("genesis", "implicitfast", "projectile"),
         pytest.param("mjx", "rk4", "tennis_racket", marks=pytest.mark.slow),   # ~1 min each: JAX compiles
         pytest.param("brax", "spring", "tennis_racket", marks=pytest.mark.slow),
         pytest.param("brax", "generalized", "projectile", marks=pytest.mark.slow)]


@pytest.mark.parametrize("engine,variant,name", CASES)
def test_the_reproducers_run_of_the_world_is_the_adapters_bit_for_bit(engine, variant, name):
    pytest.importorskip({"rapier": "rapier3d", "mjx": "mujoco.mjx", "physx": "sapien",
                         "dart": "dartpy"}.get(engine, engine))
    from cross_checks.engines import get_adapter
    from cross_checks.engines.loop import Harness
    from cross_checks.sweep import repro_measure
    from cross_checks.sweep.repro import ENGINES
    adapter_mod = importlib.import_module(ENGINES[engine][2])
    spec_mod = importlib.import_module(ENGINES[engine][3])
    world_mod = importlib.import_module(ENGINES[engine][1][-1])
    sc = load_scenario(name)
    dt, n = sc.dt_ladder_s[0], 200
    f, tau = Harness([sc], dt, adapter_mod._ENGINE.applies_gravity).wrench(sc.problem.initial_packed()[None])
    s = {"BODIES": [spec_mod.body_spec(sc.problem.body)], "GRAVITY_W": sc.problem.forces.gravity_W,
         "VARIANT": variant, "Y0": sc.problem.initial_packed(), "F_W": f[0], "TAU_W": tau[0]}
    mine = repro_measure.run(world_mod.world, s, dt, n)
    theirs = get_adapter(engine).simulate_many(variant, [RunRequest(sc, dt, n)])[0].y
    if adapter_mod._ENGINE.sign_continuity:   # the loop picks each quaternion's sign; the script need not
        mine[:, 6:10] *= np.sign(np.sum(mine[:, 6:10] * theirs[:, 6:10], axis=-1))[:, None]
    np.testing.assert_array_equal(mine[1:], theirs[1:])

"""The layering of README's "Layout" section, enforced on every import (module level and inside
functions): a module may import only from its own sub-package or from a layer below it; sub-packages
of the same layer do not import each other. No exception list."""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: (rank, package prefixes) — higher ranks may import lower ones, never the reverse.
LAYERS = [
    (0, ["reference_sim"]),
    (1, ["cross_checks.core"]),
    (2, ["cross_checks.scenario"]),
    (3, ["cross_checks.engines"]),
    (4, ["cross_checks.analysis"]),
    (5, ["cross_checks.sweep"]),
    (6, ["cross_checks.gates", "reports", "cross_checks.bench", "cross_checks.fuzz"]),
    (7, ["cross_checks.cli", "cross_checks.testing"]),
    (8, ["cross_checks.pytest_plugin"]),
]


def _unit(module: str):
    """(rank, unit) of a module: the unit is the layer's package prefix the module belongs to."""
    best = None
    for rank, prefixes in LAYERS:
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and (best is None or len(p) > len(best[1])):
                best = (rank, p)
    return best


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path):
    """Every (line, imported module) of a file, relative imports resolved, function-level ones included."""
    mod = _module_name(path)
    package = mod if path.name == "__init__.py" else mod.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield node.lineno, a.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for a in node.names:  # `from pkg import submodule` imports pkg.submodule
                yield node.lineno, (f"{target}.{a.name}" if _unit(f"{target}.{a.name}") != _unit(target)
                                    else target)


SOURCES = sorted(p for pkg in ("reference_sim", "cross_checks", "reports")
                 for p in (ROOT / pkg).rglob("*.py"))


def test_every_package_module_belongs_to_a_layer():
    orphans = [str(p.relative_to(ROOT))
               for p in SOURCES if _module_name(p) != "cross_checks" and _unit(_module_name(p)) is None]
    assert not orphans, f"modules outside every layer (add them to LAYERS and README's Layout): {orphans}"


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_point_down_the_layers(path):
    me = _unit(_module_name(path))
    if me is None:
        return
    bad = []
    for line, target in _imports(path):
        other = _unit(target)
        if other is None or other == me:
            continue
        if other[0] >= me[0]:
            bad.append(
                f"line {line}: {me[1]} (layer {me[0]}) imports {target} ({other[1]}, layer {other[0]})")
    assert not bad, "\n".join(bad)


def test_function_level_imports_are_seen():
    """cli.sweep imports reports inside its command functions only: the checker must see those imports."""
    targets = {t for _, t in _imports(ROOT / "cross_checks" / "cli" / "sweep.py")}
    assert "reports" in targets and any(t.startswith("cross_checks.sweep") for t in targets)


def test_a_backward_import_is_reported(tmp_path, monkeypatch):
    """A planted function-level import of a higher layer (engines importing the sweep) is flagged."""
    planted = ROOT / "cross_checks" / "engines" / "_planted_for_test.py"
    planted.write_text("def f():\n    from cross_checks.sweep import run_sweep\n    return run_sweep\n")
    try:
        with pytest.raises(AssertionError,
                           match="cross_checks.engines \\(layer 3\\) imports cross_checks.sweep"):
            test_imports_point_down_the_layers(planted)
    finally:
        planted.unlink()


def _module_graph(paths) -> dict:
    """module -> the package modules it imports (module level and inside functions), itself left out."""
    names = {_module_name(p) for p in paths}
    graph = {}
    for p in paths:
        me = _module_name(p)
        deps = set()
        for _, target in _imports(p):
            parts = target.split(".")   # `from a.b import c` may name a function: take the longest module
            for k in range(len(parts), 0, -1):
                cand = ".".join(parts[:k])
                if cand in names:
                    deps.add(cand)
                    break
        deps.discard(me)
        # a module importing its own package's __init__ is no circle
        graph[me] = deps - {me.rsplit(".", 1)[0]}
    return graph


def _cycles(graph) -> list:
    """Every strongly connected set of two or more modules (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_module_imports_itself_round_a_circle():
    """Function-level imports included: two modules that import each other are one module in two files."""
    assert _cycles(_module_graph(SOURCES)) == []


def test_a_planted_circle_is_found():
    graph = {"a.x": {"a.y"}, "a.y": {"a.z"}, "a.z": {"a.x"}, "a.w": {"a.x"}}
    assert _cycles(graph) == [["a.x", "a.y", "a.z"]]


def _private_accesses(path: Path, names: set) -> list:
    """``(line, "module._name")`` of every use in ``path`` of another package module's private name (one
    underscore): ``alias._name`` of an imported module, or ``from module import _name``."""
    me = _module_name(path)
    tree = ast.parse(path.read_text())
    aliases, out = {}, []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name in names:
                    aliases[a.asname or a.name] = a.name
        elif isinstance(node, ast.ImportFrom) and node.module:
            for a in node.names:
                full = f"{node.module}.{a.name}"
                if full in names:
                    aliases[a.asname or a.name] = full
                elif a.name.startswith("_") and not a.name.startswith("__") and node.module in names \
                        and node.module != me:
                    out.append((node.lineno, f"{node.module}.{a.name}"))
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases:
            target = aliases[node.value.id]
            if node.attr.startswith("_") and not node.attr.startswith("__") and target != me:
                out.append((node.lineno, f"{target}.{node.attr}"))
    return out


def test_no_package_module_reaches_into_another_s_private_names():
    """What one module uses of another is that module's interface (no underscore), so it can be changed
    knowingly: the fuzz used to reach into the MuJoCo and PyBullet adapters' private sessions and locks."""
    names = {_module_name(p) for p in SOURCES}
    bad = [f"{p.relative_to(ROOT)}:{line}: {what}" for p in SOURCES
           for line, what in _private_accesses(p, names)]
    assert not bad, "\n".join(bad)


def test_a_planted_private_access_is_found(tmp_path):
    planted = ROOT / "cross_checks" / "fuzz" / "_planted_private_for_test.py"
    planted.write_text("from cross_checks.engines import mujoco_engine as "
                       "me\n\n\ndef f():\n    return me._LOCK\n")
    try:
        names = {_module_name(p) for p in SOURCES} | {"cross_checks.engines.mujoco_engine"}
        assert _private_accesses(planted, names) == [(5, "cross_checks.engines.mujoco_engine._LOCK")]
    finally:
        planted.unlink()


def _tolerance_names(text: str) -> list:
    """The module-level names a tolerances module assigns or defines."""
    tree = ast.parse(text)
    names = [t.id for n in tree.body if isinstance(n, (ast.Assign, ast.AnnAssign))
             for t in (n.targets if isinstance(n, ast.Assign) else [n.target]) if isinstance(t, ast.Name)]
    return names + [n.name for n in tree.body if isinstance(n, ast.FunctionDef)]


def _unused_in_package(names, package_text: str) -> list:
    import re
    return [n for n in names if not re.search(rf"\b{n}\b", package_text)]


def _package_text_besides_tolerances() -> str:
    return "\n".join(p.read_text() for p in SOURCES if p.name != "tolerances.py")


def test_every_package_tolerance_is_used_by_the_package():
    """The package's tolerances module is part of the results' cache key: a number only tests use belongs in
    tests/helpers/tolerances.py, where tuning it recomputes nothing."""
    names = _tolerance_names((ROOT / "cross_checks" / "core" / "tolerances.py").read_text())
    assert len(names) > 50
    assert _unused_in_package(names, _package_text_besides_tolerances()) == []


def test_a_test_only_tolerance_in_the_package_is_found():
    names = _tolerance_names("#: a number\nTEST_ONLY_NUMBER = 1e-9\nUSED = 2\n")
    assert _unused_in_package(names, "x = tol.USED\n") == ["TEST_ONLY_NUMBER"]


#: The registry's lookups that turn an "ENGINE:VARIANT" name into what its engine declares (issue 42: the name
#: is resolved once, at the entry points, and the Resolved passed down; everything below reads its fields).
VARIANT_LOOKUPS = {"resolve", "split_variant", "declared_variant", "declared_order", "declared_traits",
                   "declared_imitation", "has_one_step", "default_variant", "not_expressible"}
#: At most this many call sites outside the registry (cross_checks/engines/__init__.py) may look a name up.
MAX_VARIANT_LOOKUP_SITES = 10


def _variant_lookups(path: Path) -> list:
    """(line, function) of every call in ``path`` to one of the registry's VARIANT_LOOKUPS: a name imported
    from cross_checks.engines (under any alias) or an attribute of that module imported under a name."""
    tree = ast.parse(path.read_text())
    names, modules = {}, set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module == "cross_checks.engines" and not node.level:
            names.update({a.asname or a.name: a.name for a in node.names if a.name in VARIANT_LOOKUPS})
        elif isinstance(node, ast.ImportFrom) and node.module == "cross_checks" and not node.level:
            modules.update(a.asname or a.name for a in node.names if a.name == "engines")
        elif isinstance(node, ast.Import):
            modules.update(a.asname for a in node.names if a.name == "cross_checks.engines" and a.asname)
    out = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        if isinstance(f, ast.Name) and f.id in names:
            out.append((node.lineno, names[f.id]))
        elif (isinstance(f, ast.Attribute) and f.attr in VARIANT_LOOKUPS and isinstance(f.value, ast.Name)
              and f.value.id in modules):
            out.append((node.lineno, f.attr))
    return sorted(out)


def variant_lookup_sites() -> list:
    registry = ROOT / "cross_checks" / "engines" / "__init__.py"
    return [f"{p.relative_to(ROOT)}:{line}: {what}" for p in SOURCES if p != registry
            for line, what in _variant_lookups(p)]


def test_variant_names_are_resolved_at_few_sites_outside_the_registry():
    """The entry points (the CLI's user input, assert_engine, the sweep's and the fuzz's plans, repro, bench)
    resolve an "ENGINE:VARIANT" once and pass the Resolved down; a module below them reads its fields and
    never looks the name up again (issue 42)."""
    sites = variant_lookup_sites()
    assert len(sites) <= MAX_VARIANT_LOOKUP_SITES, "\n".join(sites)


def test_a_planted_variant_lookup_is_counted(tmp_path):
    planted = tmp_path / "planted.py"
    planted.write_text("from cross_checks.engines import resolve as r, get_adapter\nfrom cross_checks "
                       "import engines as E\n\n\ndef f(v):\n    get_adapter('x')\n    return r(v), "
                       "E.split_variant(v), E.get_adapter(v)\n")
    assert _variant_lookups(planted) == [(7, "resolve"), (7, "split_variant")]


#: Distributions whose import starts JAX (its threads, its compiler): a test module importing one at its top
#: does so at collection, in every pytest-xdist worker, and before the sweeps that later tests fork.
JAX_IMPORTS = ("jax", "jaxlib", "jaxsim", "brax", "mujoco.mjx", "genesis")


def _collection_imports_of_jax(path: Path) -> list:
    """The module-level statements of a test file that import a JAX distribution: ``import``/``from`` and
    ``pytest.importorskip(...)`` outside any function or class."""
    found = []
    for node in ast.parse(path.read_text()).body:
        for sub in ast.walk(node):
            if isinstance(sub, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Lambda)):
                break
            names = []
            if isinstance(sub, ast.Import):
                names = [a.name for a in sub.names]
            elif isinstance(sub, ast.ImportFrom) and sub.module and not sub.level:
                names = [sub.module]
            elif (isinstance(sub, ast.Call) and getattr(sub.func, "attr", "") == "importorskip" and sub.args
                  and isinstance(sub.args[0], ast.Constant)):
                names = [sub.args[0].value]
            found += [f"{path.relative_to(ROOT)}:{sub.lineno} {n}" for n in names
                      if any(n == j or n.startswith(j + ".") for j in JAX_IMPORTS)]
    return found


def test_no_test_module_starts_jax_at_collection():
    """JAX-based engines are imported by the tests that run them (importlib.util.find_spec to skip where one
    is not installed), never at a test module's top (brax's importorskip cost every worker 4 CPU s)."""
    found = [f for p in sorted((ROOT / "tests").rglob("*.py")) for f in _collection_imports_of_jax(p)]
    assert not found, found


def test_a_planted_collection_import_of_jax_is_found(tmp_path, monkeypatch):
    f = ROOT / "tests" / "x.py"
    monkeypatch.setattr(Path, "read_text", lambda self: 'import pytest\npytest.importorskip("brax")\n'
                        'def f():\n    import jax\n')
    assert _collection_imports_of_jax(f) == [f"{f.relative_to(ROOT)}:2 brax"]

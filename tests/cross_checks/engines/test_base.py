"""The pieces of cross_checks.engines.base the adapters share: the variant check, the grouped batch runner,
the single request, ModuleAdapter's forwarding, the engine's files found without importing it, and the
plumbing of the optional engines (fd 2 silenced, the first import's error, the fork guard, the counters)."""
import os
import subprocess
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


def test_run_in_groups_keeps_the_order_splits_groups_and_gives_a_group_s_error_to_each_member():
    reqs = list(range(7))                       # stand-ins: the key and the group runner see them as they are
    calls = []

    def run_group(group):
        calls.append(group)
        if 3 in group:
            raise EngineError("three")
        return [f"run {r}" for r in group]

    out = base.run_in_groups(reqs, lambda r: r % 2, run_group, max_size=2)
    assert calls == [[0, 2], [4, 6], [1, 3], [5]]
    assert out[0::2] == ["run 0", "run 2", "run 4", "run 6"] and out[5] == "run 5"
    assert isinstance(out[1], EngineError) and out[1] is out[3]


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


def test_package_files_finds_an_installed_package_s_files_without_importing_it():
    files = base.package_files("json", pattern="*.py")
    assert any(f.name == "decoder.py" for f in files)
    assert base.package_files("json", "decoder.py") == [f for f in files if f.name == "decoder.py"]
    assert base.package_files("no_such_package_here") == []


def test_check_installed_tells_an_absent_engine_from_one_missing_what_it_runs_on(monkeypatch):
    versions = {"mysim": "1.0", "mylib": None}
    base.check_installed("mysim", "pip install mysim", version_of=versions.get)
    with pytest.raises(base.EngineNotInstalled, match=r"^othersim is not installed \(pip install x\)$"):
        base.check_installed("othersim", "pip install x", version_of=versions.get)
    said = "mysim 1.0 is installed but cannot be imported: mylib is missing"
    with pytest.raises(ImportError, match=said) as e:
        base.check_installed("mysim", "pip install mysim", (("json", "mylib"),), version_of=versions.get)
    assert not isinstance(e.value, base.EngineNotInstalled)


def test_on_rows_gives_one_step_float_rows_and_returns_the_callers_shape():
    seen = []

    @base.on_rows
    def one_step(scenario, variant, dt_s, y_start):
        seen.append((y_start.shape, y_start.dtype))
        return y_start + 1.0

    for shape in [(13,), (2, 3, 13), (0, 13)]:
        y = np.zeros(shape, dtype=np.float32)
        out = one_step(None, "v", 0.1, y)
        assert out.shape == shape and np.all(out == 1.0)
        assert seen[-1] == ((int(np.prod(shape[:-1])), 13), np.float64)


def test_quiet_fd2_silences_file_descriptor_2_for_the_block_only():
    code = ("import os\nfrom cross_checks.engines import base\nos.write(2, b'before ')\n"
            "with base.quiet_fd2():\n    os.write(2, b'hidden ')\nos.write(2, b'after')\n"
            "with base.quiet_fd2():\n    pass\nos.write(2, b'!')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert out.returncode == 0 and out.stderr == b"before after!"


def test_first_import_tells_a_broken_install_by_its_version_and_the_engine_s_words():
    with pytest.raises(ImportError, match=r"^mysim 1\.2 is installed but cannot be imported: "
                                          r"AttributeError: no attribute 'x'$") as e:
        with base.first_import("mysim", {"mysim": "1.2"}.get):
            raise AttributeError("no attribute 'x'")
    assert not isinstance(e.value, base.EngineNotInstalled)
    with base.first_import("mysim", {"mysim": "1.2"}.get):
        pass


def test_engine_or_error_makes_an_import_failure_an_engine_error():
    def broken():
        raise ImportError("mysim 1.2 is installed but cannot be imported: OSError: libmysim.so")

    with pytest.raises(EngineError, match="^mysim 1.2 is installed but cannot be imported: OSError"):
        base.engine_or_error(broken)
    assert base.engine_or_error(lambda: ("modules",)) == ("modules",)


def test_refuse_forked_jax_refuses_only_in_a_child_forked_after_jax_started(monkeypatch):
    base.refuse_forked_jax("never said")   # this process was not forked after JAX started
    monkeypatch.setattr(base, "_FORKED_AFTER_JAX", [True])
    with pytest.raises(EngineError, match="^forked: run with --jobs 1$"):
        base.refuse_forked_jax("forked: run with --jobs 1")


def test_stats_time_blocks_and_reset_to_their_zeros():
    stats = base.Stats(compilations=0, step_seconds=0.0)
    with stats.timing("step_seconds"):
        stats["compilations"] += 2
    assert stats["compilations"] == 2 and stats["step_seconds"] > 0.0
    with pytest.raises(RuntimeError), stats.timing("step_seconds"):
        raise RuntimeError("failed")
    stats.reset()
    assert dict(stats) == {"compilations": 0, "step_seconds": 0.0}


def test_a_registry_holds_a_value_under_a_fresh_key_for_the_block_only():
    reg = base.Registry()
    with reg.holding("a") as ka, reg.holding("b") as kb:
        assert isinstance(ka, np.int64) and ka != kb and reg == {int(ka): "a", int(kb): "b"}
    assert reg == {}
    with pytest.raises(RuntimeError), reg.holding("c"):
        raise RuntimeError("failed")
    assert reg == {}


def test_weight_is_mass_times_gravity_in_world_axes():
    from cross_checks.scenario import load_scenario
    sc = load_scenario("projectile")
    want = sc.problem.body.mass_kg * np.asarray(sc.problem.forces.gravity_W)
    assert base.weight_W(sc).tolist() == want.tolist()


def test_minus_weight_takes_the_weight_off_the_force_only():
    wrench = base.minus_weight(lambda y: (1.0, 2.0, 3.0 + y[0], 4.0, 5.0, 6.0), np.array([0.5, 0.0, -9.75]))
    assert wrench([0.25]) == (0.5, 2.0, 13.0, 4.0, 5.0, 6.0)


def test_batches_are_padded_to_the_next_power_of_two():
    assert [base.power_of_two(n) for n in (1, 2, 3, 4, 5, 64, 65)] == [1, 2, 4, 4, 8, 64, 128]


def test_release_reads_the_installed_versions_from_package_metadata():
    from importlib.metadata import version as dist_version
    assert base.release("numpy") == dist_version("numpy")
    on_scipy = f"{dist_version('numpy')} (scipy {dist_version('scipy')})"
    assert base.release("numpy", ("scipy", "scipy")) == on_scipy
    assert base.release("no-such-distribution-rbcheck") == "unknown"


def test_warp_with_a_kernel_cache_it_cannot_write_compiles_elsewhere_and_says_so(tmp_path):
    """Before: MuJoCo Warp with a read-only kernel cache failed every row."""
    from pathlib import Path
    pytest.importorskip("warp")
    (tmp_path / "file").write_text("")
    code = ("from cross_checks.engines.base import start_warp\n"
            "wp = start_warp('warp', 'LOG_ERROR', quiet=True)\n"
            "import warp\n"
            "@warp.kernel\n"
            "def twice(a: warp.array(dtype=float)):\n"
            "    i = warp.tid()\n"
            "    a[i] = 2.0 * a[i]\n"
            "a = warp.array([1.0, 2.0], dtype=float, device='cpu')\n"
            "warp.launch(twice, dim=2, inputs=[a], device='cpu')\n"
            "print(a.numpy().tolist(), wp.config.kernel_cache_dir)\n")
    (tmp_path / "k.py").write_text(code)   # Warp reads a kernel's source from its file
    env = {**os.environ, "RBCHECK_KERNEL_CACHE_DIR": str(tmp_path / "file")}
    proc = subprocess.run([sys.executable, str(tmp_path / "k.py")], capture_output=True, text=True,
                          timeout=600, env=env, cwd=Path(base.__file__).parents[2])
    assert proc.returncode == 0, proc.stderr[-2000:]
    values, folder = proc.stdout.strip().rsplit(" ", 1)
    assert values == "[2.0, 4.0]" and not folder.startswith(str(tmp_path))
    assert f"warp's kernel cache folder {tmp_path / 'file' / 'warp'} skipped (Not a directory)" in proc.stderr


_TWICE = """
import sys
from cross_checks.engines.base import start_warp
wp = start_warp("warp", "LOG_ERROR", quiet=True)

@wp.kernel
def twice(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = 2.0 * a[i]

a = wp.array([1.0, 2.0], dtype=float, device="cpu")
wp.launch(twice, dim=2, inputs=[a], device="cpu")
print(a.numpy().tolist())
"""


def test_warp_kernel_objects_cut_in_half_are_compiled_again(tmp_path):
    """Before: every run failed "Failed to load CPU module" until the user found the folder."""
    from pathlib import Path
    pytest.importorskip("warp")
    (tmp_path / "k.py").write_text(_TWICE)   # Warp reads a kernel's source from its file
    env = {**os.environ, "RBCHECK_KERNEL_CACHE_DIR": str(tmp_path / "kernels")}

    def run():
        return subprocess.run([sys.executable, str(tmp_path / "k.py")], capture_output=True, text=True,
                              timeout=600, env=env, cwd=Path(base.__file__).parents[2])
    assert run().stdout.strip() == "[2.0, 4.0]"
    objects = list((tmp_path / "kernels").rglob("*.o"))
    assert objects
    for o in objects:
        o.write_bytes(o.read_bytes()[: o.stat().st_size // 2])
    again = run()
    assert again.returncode == 0 and again.stdout.strip() == "[2.0, 4.0]", again.stderr[-2000:]
    [line] = [ln for ln in again.stderr.splitlines() if ln.startswith("rbcheck:")]
    assert "kernel cache entry" in line and str(tmp_path / "kernels") in line and "compiling it again" in line
    assert run().stderr.count("rbcheck:") == 0   # the entry compiled again is whole

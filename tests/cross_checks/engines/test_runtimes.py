"""cross_checks.engines.runtimes: the fork guard of JAX, the counters, the callback registry, the batch
padding, and Warp's kernel cache (a folder that cannot be written, objects cut in half)."""
import os
import subprocess
import sys

import numpy as np
import pytest

from cross_checks.engines import runtimes
from cross_checks.engines.base import EngineError


def test_refuse_forked_jax_refuses_only_in_a_child_forked_after_jax_started(monkeypatch):
    runtimes.refuse_forked_jax("never said")   # this process was not forked after JAX started
    monkeypatch.setattr(runtimes, "_FORKED_AFTER_JAX", [True])
    with pytest.raises(EngineError, match="^forked: run with --jobs 1$"):
        runtimes.refuse_forked_jax("forked: run with --jobs 1")


def test_stats_time_blocks_and_reset_to_their_zeros():
    stats = runtimes.Stats(compilations=0, step_seconds=0.0)
    with stats.timing("step_seconds"):
        stats["compilations"] += 2
    assert stats["compilations"] == 2 and stats["step_seconds"] > 0.0
    with pytest.raises(RuntimeError), stats.timing("step_seconds"):
        raise RuntimeError("failed")
    stats.reset()
    assert dict(stats) == {"compilations": 0, "step_seconds": 0.0}


def test_a_warp_engine_is_declared_by_its_fields_and_loads_each_variant_s_kernels_once(monkeypatch):
    """A WarpEngine subclass: its version and install checks from package metadata (Warp not imported), the
    pip extra named when it is absent, Warp what it runs on; its modules imported once after Warp started
    (start_warp with the engine's kernel cache, log level and quiet flag); ``warm`` runs a load once per key,
    its seconds kept and counted in the subclass's own stats."""
    from cross_checks.engines import install

    class Planted(runtimes.WarpEngine):
        name, distribution, extra = "planted", "planted-dist", "planted"
        imports, warp_log = ("json",), "LOG_X"
        stats = runtimes.Stats(compilations=0, compile_seconds=0.0)

        def build(self, requests, variant, dt_s):   # pragma: no cover - never run here
            raise AssertionError

    versions = {"planted-dist": "1.2", "warp-lang": "9.9"}
    monkeypatch.setattr(install, "installed_version", versions.get)
    monkeypatch.setattr(install, "release", lambda d, on=(): f"{versions[d]} ({on[0]} {versions[on[1]]})")
    assert Planted().version() == "1.2 (warp 9.9)"
    started = []
    monkeypatch.setattr(runtimes, "start_warp", lambda *a: started.append(a) or "wp")
    import json
    assert Planted().modules() == ("wp", json) and Planted().modules() == ("wp", json)
    assert started == [("planted", "LOG_X", False)]
    loads = []
    Planted().warm("euler", lambda: loads.append(1))
    Planted().warm("euler", lambda: loads.append(2))
    assert loads == [1] and set(Planted.warmed) == {"euler"}
    assert Planted.stats["compilations"] == 1 and Planted.stats["compile_seconds"] == Planted.warmed["euler"]
    del versions["planted-dist"]
    with pytest.raises(install.EngineNotInstalled, match=r"planted-dist is not installed .*\[planted\]"):
        Planted().version()


def test_a_registry_holds_a_value_under_a_fresh_key_for_the_block_only():
    reg = runtimes.Registry()
    with reg.holding("a") as ka, reg.holding("b") as kb:
        assert isinstance(ka, np.int64) and ka != kb and reg == {int(ka): "a", int(kb): "b"}
    assert reg == {}
    with pytest.raises(RuntimeError), reg.holding("c"):
        raise RuntimeError("failed")
    assert reg == {}


def test_batches_are_padded_to_the_next_power_of_two():
    assert [runtimes.power_of_two(n) for n in (1, 2, 3, 4, 5, 64, 65)] == [1, 2, 4, 4, 8, 64, 128]


def test_a_chunk_records_at_most_chunk_rows_rows_and_at_least_64_steps():
    # a thousand bodies record 128 steps a call (13.6 MB), a sweep's ladder of a few runs the longest chunk
    assert [runtimes.chunk_rows(b, 2048) for b in (1, 8, 64, 128, 1024, 1 << 20)] == [2048, 2048, 2048, 1024,
                                                                                      128, 64]
    assert runtimes.chunk_rows(4, 512) == 512
    assert all(runtimes.chunk_rows(b, 4096) * b <= runtimes.CHUNK_ROWS for b in (64, 256, 1024, 2048))


def test_stacked_trees_give_each_body_its_own_tree_s_leaves():
    import importlib.util
    if importlib.util.find_spec("jax") is None:
        pytest.skip("jax is not installed")
    runtimes.start_jax()
    a = {"m": np.array([1.0, 2.0]), "dt": np.float64(0.01)}
    b = {"m": np.array([3.0, 4.0]), "dt": np.float64(0.02)}
    out = runtimes.stack_trees([a, b], [1, 0, 0])
    np.testing.assert_array_equal(out["m"], [[3.0, 4.0], [1.0, 2.0], [1.0, 2.0]])
    np.testing.assert_array_equal(out["dt"], [0.02, 0.01, 0.01])


def test_warp_with_a_kernel_cache_it_cannot_write_compiles_elsewhere_and_says_so(tmp_path):
    """Before: MuJoCo Warp with a read-only kernel cache failed every row."""
    from pathlib import Path
    pytest.importorskip("warp")
    (tmp_path / "file").write_text("")
    code = ("from cross_checks.engines.runtimes import start_warp\n"
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
                          timeout=600, env=env, cwd=Path(runtimes.__file__).parents[2])
    assert proc.returncode == 0, proc.stderr[-2000:]
    values, folder = proc.stdout.strip().rsplit(" ", 1)
    assert values == "[2.0, 4.0]" and not folder.startswith(str(tmp_path))
    assert f"warp's kernel cache folder {tmp_path / 'file' / 'warp'} skipped (Not a directory)" in proc.stderr


_TWICE = """
import sys
from cross_checks.engines.runtimes import start_warp
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
                              timeout=600, env=env, cwd=Path(runtimes.__file__).parents[2])
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


def _jax_or_skip():
    import importlib.util
    if importlib.util.find_spec("jax") is None:
        pytest.skip("jax is not installed")
    return runtimes.start_jax()


def test_jaxs_persistent_cache_is_rbchecks_kernel_cache_never_the_result_cache(tmp_path):
    """What the JAX engines share (it was each adapter's own ``xla_cache_dir``/``jax_cache_dir``)."""
    from pathlib import Path
    _jax_or_skip()
    env = {**os.environ, "RBCHECK_KERNEL_CACHE_DIR": str(tmp_path / "k"),
           "RBCHECK_CACHE_DIR": str(tmp_path / "r")}
    code = ("from cross_checks.engines.runtimes import start_jax\n"
            "print(start_jax().config.jax_compilation_cache_dir)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, env=env,
                          cwd=Path(runtimes.__file__).parents[2])
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == str(tmp_path / "k" / "jax")


class _Planted(runtimes.JaxEngine):
    name, variants, distribution, module, extra, needs = "planted", {}, "numpy", "numpy", "planted", ()

    def build(self, requests, variant, dt_s):   # pragma: no cover - never stepped here
        raise NotImplementedError


def test_a_jax_engines_version_and_install_checks_come_from_its_declarations(monkeypatch):
    from cross_checks.engines import install
    assert _Planted().version() == install.installed_version("numpy")
    monkeypatch.setattr(_Planted, "needs", (("no_such_module_rbcheck", "numpy"),))
    with pytest.raises(ImportError, match="numpy .* is installed but cannot be imported: numpy is missing"):
        _Planted().version()
    monkeypatch.setattr(_Planted, "distribution", "no-such-dist-rbcheck")
    with pytest.raises(install.EngineNotInstalled,
                       match=r"^no-such-dist-rbcheck is not installed \(pip install 'rbcheck\[planted\]'\)$"):
        _Planted().version()


def test_each_jax_engine_counts_its_own_compilations_once_per_key_and_shape():
    _jax_or_skip()

    class Other(_Planted):
        pass
    engine, calls = _Planted(), []

    def make():
        calls.append(1)
        return lambda x: 2.0 * x
    double = engine.compiled("double", make, np.ones(3), name="double")
    np.testing.assert_array_equal(np.asarray(double(np.arange(3.0))), [0.0, 2.0, 4.0])
    assert engine.compiled("double", make, np.zeros(3), name="double") is double        # same key and shape
    assert engine.compiled("double", make, np.ones(4), name="double") is not double     # another shape
    assert len(calls) == 2 and engine.timings()["compilations"] == 2
    assert engine.per_executable["double"] == engine.compile_seconds > 0.0
    assert Other().timings()["compilations"] == 0                                        # counters per engine
    with pytest.raises(EngineError, match=r"^planted/XLA could not compile the step: TypeError"):
        engine.compiled("bad", lambda: (lambda x: x + "a"), np.ones(3))


def test_a_recorded_loop_runs_its_count_and_records_each_state():
    jax = _jax_or_skip()
    loop = jax.jit(runtimes.recorded(lambda s: s + 1.0, lambda s: s * np.ones(13), 8))
    state, rows = loop(np.float64(10.0), np.int64(3))
    assert float(state) == 13.0
    np.testing.assert_array_equal(np.asarray(rows)[:, 0], [11.0, 12.0, 13.0, 0, 0, 0, 0, 0])


class _Chunked(runtimes.JaxWorld):
    engine = _Planted

    def __init__(self, ends):
        super().__init__()
        self.ends, self.host_s = ends, 0.0


def test_a_batch_stops_after_the_chunk_in_which_every_body_ended_or_blew_up():
    world, asked = _Chunked([3, 100, 100]), []
    before = dict(_Planted.stats)

    def call(count):   # body 1 blows up (beyond 1e8) at its 5th step, body 2 becomes NaN at its 6th
        k = sum(asked)
        asked.append(count)
        steps = np.arange(k + 1, k + count + 1, dtype=float)[None, :, None] * np.ones((4, 1, 13))
        steps[1, steps[1, :, 0] >= 5] = 1e9
        steps[2, steps[2, :, 0] >= 6] = np.nan
        return steps
    out = np.full((20, 3, 13), -1.0)
    world.chunks(call, 20, 4, [0, 1, 2], out)
    assert asked == [4, 4]                               # all three ended in the second chunk: no third
    np.testing.assert_array_equal(out[:8, 0, 0], np.arange(1.0, 9.0))
    assert np.all(out[8:] == -1.0)                       # rows never computed are left as they were
    assert _Planted.stats["body_steps"] - before["body_steps"] == 24
    # finite_only: a body beyond 1e8 but finite goes on (MJX's raw rows are not the packed state)
    world, asked = _Chunked([100, 100, 100]), []
    world.chunks(call, 12, 4, [0, 1, 2], out, finite_only=True)
    assert asked == [4, 4, 4]


def test_a_jax_worlds_rollout_gives_what_is_not_a_compiled_call_to_the_host(monkeypatch):
    clock = iter(np.arange(0.0, 100.0))
    monkeypatch.setattr(runtimes.time, "perf_counter", lambda: float(next(clock)))

    class World(_Chunked):
        def run(self, n_steps, harness):   # two ticks of host work, then a compiled call of one tick
            runtimes.time.perf_counter()
            out = np.zeros((n_steps, 1, 13))
            self.chunks(lambda count: np.zeros((1, count, 13)), n_steps, n_steps, [0], out)
            return out
    world = World([5])
    monkeypatch.setattr(_Planted, "stats", runtimes.Stats(compilations=0, compile_seconds=0.0,
                                                          step_seconds=0.0, body_steps=0))
    assert world.rollout(5, None).shape == (5, 1, 13)   # 0 start, 1 host, 2-3 the call, 4 end
    assert _Planted.stats["step_seconds"] == 1.0 and world.host_s == 3.0

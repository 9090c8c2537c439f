"""A world's whole record of MuJoCo rows as packed states in each run's own layout: the compiled kernel's
numbers are worlds.mujoco.to_packed's bit for bit (signed zeros, NaN, infinities, magnitudes from 1e-30 to
1e30 included), the result's per-run copy costs nothing, and without numba it is the NumPy conversion."""
import numpy as np
import pytest

from cross_checks.engines import packed_rows

mjw = pytest.importorskip("cross_checks.engines.worlds.mujoco")


def _numpy(raw):
    return mjw.to_packed(raw[..., 0:7], raw[..., 7:13])


def _raw(n=37, B=29, seed=5):
    rng = np.random.default_rng(seed)
    raw = rng.standard_normal((n, B, 13)) * rng.choice([1e-30, 1.0, 1e30], size=(n, B, 13))
    q = rng.standard_normal((n, B, 4))
    raw[..., 3:7] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    raw[1, 2, 4], raw[2, 3, 11], raw[3, 4, 12], raw[4, 5, 10] = np.nan, np.inf, -np.inf, -0.0
    raw[5, 6, 3:7] = [-0.0, 0.0, -0.0, 1.0]
    return raw


def test_the_kernel_gives_to_packeds_numbers_bit_for_bit_in_each_runs_layout():
    raw = _raw()
    with np.errstate(all="ignore"):
        want = _numpy(raw)
        got = packed_rows.qpos_qvel_packed(raw, _numpy)
    assert got.shape == want.shape == raw.shape
    assert np.array_equal(np.ascontiguousarray(got).view(np.uint64), want.view(np.uint64))
    per_run = np.swapaxes(got, 0, 1)   # what the loop hands each run: no copy of the record
    assert per_run.flags.c_contiguous and np.ascontiguousarray(per_run) is per_run


def test_a_strided_record_is_converted_as_its_contiguous_copy():
    raw = _raw(20, 11)
    view = np.concatenate([raw, raw], axis=1)[:, ::2]
    with np.errstate(all="ignore"):
        got = np.ascontiguousarray(packed_rows.qpos_qvel_packed(view, _numpy))
        assert np.array_equal(got.view(np.uint64), _numpy(np.ascontiguousarray(view)).view(np.uint64))


def test_other_shapes_and_no_numba_take_the_numpy_conversion(monkeypatch):
    raw = _raw(8, 7)
    calls = []

    def numpy_packed(r):
        calls.append(r.shape)
        return _numpy(r)
    with np.errstate(all="ignore"):
        packed_rows.qpos_qvel_packed(raw[0], numpy_packed)               # one read (B, 13)
        monkeypatch.setattr(packed_rows, "_kernels", lambda: None)
        got = packed_rows.qpos_qvel_packed(raw, numpy_packed)
    assert calls == [(7, 13), (8, 7, 13)]
    with np.errstate(all="ignore"):
        assert np.array_equal(got.view(np.uint64), _numpy(raw).view(np.uint64))


@pytest.mark.parametrize("module", ["mujoco_engine", "mujoco_warp_engine"])
def test_the_kernels_file_is_in_the_mujoco_engines_cache_key(module):
    # packed_rows among the engine's harness modules lists its kernels' file itself (WorldEngine.source_files)
    import importlib
    engine = next(v for k, v in vars(importlib.import_module(f"cross_checks.engines.{module}")).items()
                  if k.endswith("Engine") and isinstance(v, type) and v.__module__.endswith(module))
    names = {p.name for p in engine().source_files()}
    assert {"packed_rows.py", "_packed_kernels.py"} <= names

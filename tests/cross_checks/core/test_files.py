"""Unbounded memory from files someone else wrote (issue 45): .npz members are sized from their npy headers
before any is read; a cache .secret that is a symlink to /dev/zero is never read whole."""
import io
import os
import shutil
import zipfile

import numpy as np
import pytest

from cross_checks.core.files import npz_array_bytes

#: The issue's bomb: members whose headers claim 2.5e8 float64 elements each (2 GB to read); only the header
#: is written (the data would be zeros, compressing to ~1 MB each): a reader that trusts it allocates 2 GB.
N_BOMB = 250_000_000


def _bomb(path, names):
    with zipfile.ZipFile(path, "w") as zf:
        for name in names:
            buf = io.BytesIO()
            np.lib.format.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False,
                                                       "shape": (N_BOMB,)})
            zf.writestr(f"{name}.npy", buf.getvalue() + b"\0" * 64)


def test_member_sizes_come_from_the_headers(tmp_path):
    _bomb(tmp_path / "b.npz", ["a", "b"])
    assert npz_array_bytes(tmp_path / "b.npz") == {"a": 8 * N_BOMB, "b": 8 * N_BOMB}


def test_a_report_refuses_a_series_file_too_large_to_read_before_reading_it(tiny_results, tmp_path):
    from reports.data import ResultsError, load_results
    res = tmp_path / "res"
    shutil.copytree(tiny_results, res)
    _bomb(res / "series" / "tiny.npz", ["reference:course::t_s", "reference:course::x_W"])
    with pytest.raises(ResultsError, match=r"tiny\.npz: cannot read: .*would take 3815 MiB to read"):
        load_results(res).series("tiny")


def test_a_cache_entry_too_large_is_not_read_and_is_removed(tmp_path):
    from cross_checks.sweep import cache
    good = tmp_path / "good.npz"
    cache.store(tmp_path, good, "k" * 64, {"x": np.arange(3.0)})
    assert cache.load(tmp_path, good, "k" * 64)["x"].tolist() == [0.0, 1.0, 2.0]
    bomb = tmp_path / "bomb.npz"
    _bomb(bomb, ["x", "__key__", "__mac__"])   # even its key member claims 2 GB
    assert cache.load(tmp_path, bomb, "k" * 64) is None and not bomb.exists()


def test_a_secret_that_is_a_link_to_dev_zero_is_replaced_not_read(tmp_path):
    from cross_checks.sweep import cache
    os.symlink("/dev/zero", tmp_path / ".secret")
    secret = cache._secret(tmp_path)
    assert len(secret) == 32 and not (tmp_path / ".secret").is_symlink()
    assert (tmp_path / ".secret").read_bytes() == secret


def test_a_kernel_cache_folder_that_cannot_be_written_is_replaced_by_a_private_one(tmp_path, capsys):
    from cross_checks.core.files import usable_cache_dir
    (tmp_path / "file").write_text("")
    bad = tmp_path / "file" / "warp"   # below a regular file: no one can create it, root included
    first, again = usable_cache_dir(bad, "warp's kernel"), usable_cache_dir(bad, "warp's kernel")
    assert first == again and first.is_dir() and not first.is_relative_to(tmp_path)
    (first / "k.o").write_bytes(b"x")   # usable
    [line] = capsys.readouterr().err.splitlines()
    assert line.startswith(f"rbcheck: warp's kernel cache folder {bad} skipped (Not a directory); using ")
    good = tmp_path / "good"
    assert usable_cache_dir(good, "warp's kernel") == good and good.is_dir()

"""The job and reference cache: an entry that does not verify (truncated, bit-flipped, empty, copied
under another key, forged numbers) is recomputed and replaced, never trusted, never a crash."""
import json
from pathlib import Path

import numpy as np
import pytest

from cross_checks.engines import resolve
from cross_checks.scenario import parse_scenario
from cross_checks.sweep import cache
from cross_checks.sweep.cache import entry_path as _cache_file
from cross_checks.sweep.jobs import Job, _job_key, reference_job, run_job_group
from tests.helpers.scenarios import TINY
from tests.helpers.sweeps import RUN_DEPENDENT_COLUMNS

SC = parse_scenario(TINY, "tiny.toml")
JOB = Job(0, "tiny", resolve("reference:rk4"), 0.01, True, True, 1.0)
OTHER = Job(0, "tiny", resolve("reference:course"), 0.01, True, True, 1.0)


def run_job(job, *args):
    return run_job_group([job], *args)[0]


def _numbers(rec):
    """The record's row without timing, NaN made comparable (NaN != NaN)."""
    return {k: ("nan" if isinstance(v, float) and v != v else v) for k, v in rec["row"].items()
            if k not in RUN_DEPENDENT_COLUMNS}


@pytest.fixture
def setup(tmp_path):
    root = tmp_path / "cache"
    ref = str(tmp_path / "ref.npz")
    assert reference_job(SC, ref, str(root), True)[1] == ""
    truth = run_job(JOB, SC, ref, None, False)  # computed without any cache
    first = run_job(JOB, SC, ref, str(root), True)
    assert not first["row"]["cached"]
    entry = _cache_file(root, "job", _job_key(SC, JOB.variant, JOB.dt_s, first["row"]["engine_version"]))
    assert entry.is_file() and run_job(JOB, SC, ref, str(root), True)["row"]["cached"]
    return root, ref, truth, entry


def _assert_recomputed_and_replaced(root, ref, truth):
    again = run_job(JOB, SC, ref, str(root), True)
    assert not again["row"]["cached"] and _numbers(again) == _numbers(truth)
    third = run_job(JOB, SC, ref, str(root), True)  # the bad entry was replaced by a good one
    assert third["row"]["cached"] and _numbers(third) == _numbers(truth)


def _truncate(p: Path):
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])


def _flip_a_bit(p: Path):
    """Flip one bit inside the stored bytes of the first array (not in zip metadata nobody reads)."""
    import struct
    import zipfile
    with zipfile.ZipFile(p) as z:
        info = z.infolist()[0]
    data = bytearray(p.read_bytes())
    name_len, extra_len = struct.unpack("<HH", data[info.header_offset + 26: info.header_offset + 30])
    start = info.header_offset + 30 + name_len + extra_len
    data[start + info.compress_size // 2] ^= 0x01
    p.write_bytes(bytes(data))


def _empty(p: Path):
    p.write_bytes(b"")


def _forge(p: Path):
    with np.load(p, allow_pickle=False) as d:
        arrays = {k: d[k] for k in d.files}
    rec = json.loads(str(arrays["__json__"]))
    rec["row"]["orient_err_final"] = 1e-300  # a too-good number, the key and MAC kept as they were
    arrays["__json__"] = np.array(json.dumps(rec))
    np.savez_compressed(p, **arrays)


@pytest.mark.parametrize("damage", [_truncate, _flip_a_bit, _empty, _forge])
def test_a_damaged_job_entry_is_recomputed_and_replaced(setup, damage):
    root, ref, truth, entry = setup
    damage(entry)
    _assert_recomputed_and_replaced(root, ref, truth)


def test_an_entry_copied_under_another_key_is_not_taken_for_it(setup):
    root, ref, truth, entry = setup
    other = run_job(OTHER, SC, ref, None, False)
    other_entry = _cache_file(root, "job",
                              _job_key(SC, OTHER.variant, OTHER.dt_s, other["row"]["engine_version"]))
    other_entry.parent.mkdir(parents=True, exist_ok=True)
    other_entry.write_bytes(entry.read_bytes())  # rk4's record under course's key
    got = run_job(OTHER, SC, ref, str(root), True)
    assert not got["row"]["cached"] and got["row"]["engine"] == "reference:course"
    assert _numbers(got) == _numbers(other)


def test_a_damaged_or_empty_reference_entry_is_recomputed(tmp_path):
    root = tmp_path / "cache"
    ref1, ref2 = str(tmp_path / "r1.npz"), str(tmp_path / "r2.npz")
    assert reference_job(SC, ref1, str(root), True)[1] == ""
    [entry] = list((root / "reference").rglob("*.npz"))
    with np.load(ref1) as d:
        y_true = d["y"]
    for damage in (_truncate, _flip_a_bit, _empty):
        damage(entry)
        label, err, *_ = reference_job(SC, ref2, str(root), True)
        assert err == "" and label == "analytic"
        with np.load(ref2) as d:
            np.testing.assert_array_equal(d["y"], y_true)
    # an empty reference with a valid MAC (written through the cache itself) is refused too
    key = str(np.load(entry)["__key__"])
    cache.store(root, entry, key, {"t_s": np.zeros(0), "y": np.zeros((0, 13)), "label": np.array("analytic")})
    assert reference_job(SC, ref2, str(root), True)[1] == ""
    with np.load(ref2) as d:
        np.testing.assert_array_equal(d["y"], y_true)


def test_the_secret_is_private_to_its_owner(setup):
    root = setup[0]
    assert ((root / ".secret").stat().st_mode & 0o777) == 0o600

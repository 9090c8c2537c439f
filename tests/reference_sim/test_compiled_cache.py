"""numba's cache is a cache (issue 45): a folder it cannot write, or files cut in half, are skipped, said once
(folder and reason) and the functions compiled in memory, with the same results. Shown on a one-function
module loaded by reference_sim.compiled.load_compiled, the loader of the reference's kernels (compiling
those takes minutes; the mechanism is the same)."""
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

pytest.importorskip("numba")

KERNEL = textwrap.dedent("""
    from numba import njit
    from tinyk_flag import FLAG

    @njit(cache=FLAG[0])
    def f(x):
        return x * 2.0 + 1.0
""")
RUN = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[1])
    import tinyk_flag
    from reference_sim.compiled import load_compiled
    m = load_compiled("tinyk", lambda m: m.f(1.0), tinyk_flag.FLAG)
    print(m.f(3.0), tinyk_flag.FLAG[0])
""")


def _run(src: Path, cache: Path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    return subprocess.run([sys.executable, "-c", RUN, str(src)], capture_output=True, text=True, timeout=300,
                          env=env, cwd=Path(__file__).parents[2])


@pytest.fixture
def module(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    (src / "tinyk.py").write_text(KERNEL)
    (src / "tinyk_flag.py").write_text("FLAG = [True]\n")
    return src


def test_a_usable_cache_is_used_silently(module, tmp_path):
    proc = _run(module, tmp_path / "cache")
    assert proc.returncode == 0 and proc.stdout.split() == ["7.0", "True"] and proc.stderr == "", proc.stderr
    assert list((tmp_path / "cache").rglob("*.nbi"))


def test_cache_files_cut_in_half_are_skipped_once_and_compiled_in_memory(module, tmp_path):
    cache = tmp_path / "cache"
    assert _run(module, cache).returncode == 0
    for f in cache.rglob("*.nb*"):
        data = f.read_bytes()
        f.write_bytes(data[: len(data) // 2])
    proc = _run(module, cache)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["7.0", "False"]
    [line] = proc.stderr.splitlines()
    assert "numba's cache folder" in line and "skipped" in line and str(cache) in line


def test_a_cache_folder_that_cannot_be_written_is_skipped_and_the_installation_left_alone(module, tmp_path):
    (tmp_path / "file").write_text("")
    proc = _run(module, tmp_path / "file" / "numba")   # below a regular file: no one can create it
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["7.0", "False"]
    [line] = proc.stderr.splitlines()
    assert f"{tmp_path / 'file' / 'numba'} skipped (cannot write there" in line
    assert not list(module.rglob("*.nb*"))   # numba did not fall back to the source's __pycache__


@pytest.mark.slow
def test_the_reference_s_kernels_with_their_cache_cut_in_half_give_the_same_trajectory(tmp_path):
    """The issue's case on the real kernels (each compile takes minutes: slow): numba's cache files of the
    reference cut in half made every run that touches the reference exit 2 "internal error: UnpicklingError".
    The trajectory must be the one written with a whole cache, digit for digit."""
    from tests.helpers.scenarios import TINY
    (tmp_path / "tiny.toml").write_text(TINY)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"), "RBCHECK_CACHE_DIR": str(tmp_path / "c")}

    def run(name):
        return subprocess.run([sys.executable, "-m", "cross_checks.cli", "run", str(tmp_path / "tiny.toml"),
                               "--engine", "reference:rk4", "--out", str(tmp_path / f"{name}.csv")],
                              capture_output=True, text=True, timeout=1800, env=env,
                              cwd=Path(__file__).parents[2])
    whole = run("whole")
    assert whole.returncode == 0, whole.stderr
    files = list((tmp_path / "numba").rglob("*.nb*"))
    assert files
    for f in files:
        data = f.read_bytes()
        f.write_bytes(data[: len(data) // 2])
    cut = run("cut")
    assert cut.returncode == 0, cut.stderr
    assert (tmp_path / "cut.csv").read_text() == (tmp_path / "whole.csv").read_text()
    assert [ln for ln in cut.stderr.splitlines() if "numba's cache folder" in ln and "skipped" in ln]


#: Loads tinyk like RUN, its first call made after ``sys.argv[3]`` seconds (a slow compile, as the reference's
#: kernels' minute), and prints whether this process compiled f or loaded it from the cache.
RACE = textwrap.dedent("""
    import sys, time
    sys.path.insert(0, sys.argv[1])
    import tinyk_flag
    from reference_sim.compiled import load_compiled
    open(sys.argv[2], "w").close()   # started
    m = load_compiled("tinyk", lambda m: (time.sleep(float(sys.argv[3])), m.f(1.0)), tinyk_flag.FLAG)
    s = m.f.stats
    print("compiled" if s.cache_misses else "loaded" if s.cache_hits else "?")
""")


def test_a_process_that_starts_while_another_compiles_waits_and_loads_its_cache(module, tmp_path):
    """Both workers of `pytest -n 2` in a fresh clone (and the sweeps their tests start) used to compile the
    reference's kernels each (a minute of CPU each): the second to come now waits for the first's cache
    (load_compiled's lock beside the cache files) and loads it. Here the first takes 2 s to compile and the
    second starts during that time."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    cwd = Path(__file__).parents[2]
    first = subprocess.Popen([sys.executable, "-c", RACE, str(module), str(tmp_path / "a"), "2.0"], env=env,
                             cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    while not (tmp_path / "a").exists() and first.poll() is None:
        time.sleep(0.01)
    time.sleep(0.5)   # the first is inside its first calls
    second = subprocess.run([sys.executable, "-c", RACE, str(module), str(tmp_path / "b"), "0"], env=env,
                            cwd=cwd, capture_output=True, text=True, timeout=120)
    out, err = first.communicate(timeout=120)
    assert first.returncode == 0 and second.returncode == 0, err + second.stderr
    assert (out.strip(), second.stdout.strip()) == ("compiled", "loaded"), err + second.stderr

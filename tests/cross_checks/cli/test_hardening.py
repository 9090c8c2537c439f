"""Hardening, third round (docs/hardening.md): each class of failure planted, and what rbcheck guarantees —
exit code, one line naming the file or option, nothing already written lost or touched."""
import os
import subprocess
import sys

import pytest

from cross_checks.cli import main
from tests.helpers.repo import BASELINE


def _one_line(capsys, command):
    err = capsys.readouterr().err
    assert (err.startswith(f"rbcheck {command}: error: ")
            and err.count("\n") == 1 and "Traceback" not in err), err
    return err


def _tree(folder):
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


# --- an input is never destroyed ------------------------------------------------------------------------

@pytest.fixture
def trajectory(tmp_path):
    path = tmp_path / "good.csv"
    assert main(["run", "projectile", "--engine", "reference:course", "--out", str(path)]) == 0
    return path


@pytest.mark.parametrize("target", ["good.csv", "good.json", "my.toml", "link.csv"])
def test_check_never_writes_over_what_it_reads(trajectory, tmp_path, capsys, target):
    scen = tmp_path / "my.toml"
    from cross_checks.scenario import catalog_path
    scen.write_text(catalog_path("projectile").read_text())
    (tmp_path / "link.csv").symlink_to(trajectory)
    before = _tree(tmp_path)
    capsys.readouterr()
    assert main(["check", str(trajectory), "--scenario", str(scen), "--json", str(tmp_path / target)]) == 2
    assert "this command reads; writing there would destroy its input" in _one_line(capsys, "check")
    assert _tree(tmp_path) == before


def test_compare_and_baseline_never_write_into_their_inputs(tmp_path, capsys):
    import shutil
    base = tmp_path / "base"
    shutil.copytree(BASELINE, base)
    before = _tree(base)
    assert main(["compare", str(base), str(base), "--markdown", str(base / "summary.json")]) == 2
    assert "lies inside the baseline directory" in _one_line(capsys, "compare")
    assert main(["baseline", str(base), str(base)]) == 2
    assert "is the results directory" in _one_line(capsys, "baseline")
    assert _tree(base) == before


def test_a_sweep_out_holding_its_own_scenario_file_is_refused(tmp_path, capsys):
    """The scenario copy a previous sweep wrote into DIR/scenarios/, swept again into
    DIR: DIR would be replaced."""
    out = tmp_path / "res"
    assert main(["sweep", "projectile", "--engines", "reference:course", "--out", str(out)]) in (0, 1)
    before = _tree(out)
    capsys.readouterr()
    copy = out / "scenarios" / "projectile.toml"
    assert copy.is_file()
    assert main(["sweep", str(copy), "--engines", "reference:course", "--out", str(out)]) == 2
    assert "holds the scenario file" in _one_line(capsys, "sweep")
    assert _tree(out) == before


# --- bounded work ----------------------------------------------------------------------------------------

def test_check_of_an_endless_file_is_refused_after_one_line(capsys):
    assert main(["check", "/dev/zero", "--scenario", "projectile"]) == 2
    assert "/dev/zero: line 1: longer than 65536 bytes: not a trajectory CSV" in _one_line(capsys, "check")


def test_check_refuses_more_rows_than_any_run_records(tmp_path, capsys, monkeypatch):
    import cross_checks.core.trajectory as T
    monkeypatch.setattr(T, "_limits", lambda: (50, 65536, 2 ** 30))   # the real limit: ~1.95e6 rows
    path = tmp_path / "long.csv"
    path.write_text("t,x,y,z\n" + "".join(f"{i * 0.01},0,0,0\n" for i in range(60)))
    assert main(["check", str(path), "--scenario", "projectile"]) == 2
    assert "rows: more than 50 rows" in _one_line(capsys, "check")


@pytest.mark.parametrize("argv, words", [
    (["fuzz", "--budget", "1e308", "--out", "{tmp}/f"], "--budget: must be at most 1e+06 s"),
    (["sweep", "projectile", "--time-limit", "1e308", "--out", "{tmp}/s"],
     "--time-limit: must be at most 1e+06 s"),
    (["sweep", "projectile", "--jobs", "100000", "--out", "{tmp}/s"], "--jobs: must be at most 1024"),
])
def test_option_numbers_are_range_checked(tmp_path, capsys, argv, words):
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err and not (tmp_path / "s").exists()


def test_show_refuses_a_step_beyond_the_limit(capsys):
    assert main(["show", "projectile", "--dt", "1e-300"]) == 2
    assert "--dt: 1e-300 s makes 1e+300 steps" in _one_line(capsys, "show")


def test_a_sweep_starts_no_more_workers_than_it_has_runs(tmp_path):
    from cross_checks.scenario import load_scenario
    from cross_checks.sweep import run_sweep
    s = run_sweep([load_scenario("projectile")], ["reference:course"], tmp_path / "r", jobs=1000,
                  use_cache=False, progress=False)
    assert s["run"]["jobs"] <= 6   # 5 runs and 1 reference


@pytest.mark.parametrize("key, value, field", [
    ("mass", "1e-300", "body.mass"),
    ("angular_velocity", "[1e300, 0.0, 0.0]", "initial.angular_velocity"),
    ("velocity", "[1e9, 0.0, 0.0]", "initial.velocity"),
])
def test_physical_numbers_beyond_the_ranges_are_refused_naming_the_field(tmp_path, capsys, key, value, field):
    from cross_checks.scenario import catalog_path
    text = catalog_path("applied_torque").read_text()
    table = "[body]" if key == "mass" else "[initial]"
    lines = [ln for ln in text.splitlines() if not ln.startswith(f"{key} =")]
    text = "\n".join(lines).replace(table, f"{table}\n{key} = {value}", 1)
    path = tmp_path / "wild.toml"
    path.write_text(text)
    assert main(["check", "/dev/null", "--scenario", str(path)]) == 2
    err = _one_line(capsys, "check")
    assert f"wild.toml: {field}: " in err and "outside the range rbcheck judges" in err


# --- output anywhere -------------------------------------------------------------------------------------

def _cli(argv, env_extra=None, **kw):
    env = {**os.environ, "MPLBACKEND": "Agg", **(env_extra or {})}
    return subprocess.run([sys.executable, "-m", "cross_checks.cli", *argv], env=env, capture_output=True,
                          timeout=300, **kw)


@pytest.mark.parametrize("argv", [["show", "tennis_racket"], ["compare", str(BASELINE), str(BASELINE)],
                                  ["check", "{traj}", "--scenario", "projectile"]])
def test_an_ascii_locale_gets_ascii_words_not_an_error(trajectory, argv):
    proc = _cli([a.format(traj=trajectory) for a in argv], {"PYTHONIOENCODING": "ascii"})
    assert proc.returncode == 0, proc.stderr.decode()
    proc.stdout.decode("ascii")   # every byte ASCII
    assert b"Traceback" not in proc.stderr


def test_a_reader_that_goes_away_never_stops_the_sweep(tmp_path):
    out = tmp_path / "res"
    cmd = (f"{sys.executable} -m cross_checks.cli sweep projectile --engines reference:course reference:rk4 "
           f"--jobs 1 --no-cache --out {out} | head -1; exit ${{PIPESTATUS[0]}}")
    proc = subprocess.run(["bash", "-c", cmd], env={**os.environ, "MPLBACKEND": "Agg",
                                                     "RBCHECK_CACHE_DIR": str(tmp_path / "cache")},
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert len(proc.stdout.splitlines()) == 1 and "Traceback" not in proc.stderr
    assert (out / "index.html").is_file() and (out / "summary.json").is_file()


def test_two_failed_runs_are_never_said_to_differ(tmp_path):
    """Both MuJoCo implicit variants refuse a body below mjMINVAL (handed through the Python API): their rows
    fail, and no agreement record claims the same scheme gave different results."""
    pytest.importorskip("mujoco")
    from cross_checks.cli.sweep import _gate_failures
    from cross_checks.scenario import load_scenario
    from cross_checks.sweep import run_sweep
    from tests.helpers.scenarios import with_body
    sc = with_body(load_scenario("projectile"), 1e-20, 1e-20)
    s = run_sweep([sc], ["mujoco:implicit", "mujoco:implicitfast"], tmp_path / "r", jobs=1, use_cache=False,
                  progress=False)
    assert s["run"]["failed_runs"] == 10 and s["agreement"] == []
    assert not [f for f in _gate_failures(s) if "differ" in f]


# --- the cache key covers what a run depends on --------------------------------------------------------

def test_a_built_in_engine_s_cache_key_covers_its_loaded_library():
    """MuJoCo's key was its version string only: now its shared library (and PyBullet's extension, Drake's
    libdrake.so where installed) is in the files the key hashes."""
    from cross_checks.engines import get_adapter
    names = {e: [p.name for p in get_adapter(e).source_files()] for e in ("mujoco", "pybullet")}
    assert any(n.startswith("libmujoco.so") for n in names["mujoco"]), names
    assert any(n.startswith("pybullet") and ".so" in n for n in names["pybullet"]), names


def test_a_changed_source_file_changes_an_adapter_s_key(tmp_path):
    from cross_checks.engines.base import EngineAdapter
    lib = tmp_path / "libsim.so"
    lib.write_bytes(b"version one")

    class Sim(EngineAdapter):
        name = "sim"

        def version(self):
            return "1"

        def simulate(self, scenario, variant, dt_s, n_steps):
            raise NotImplementedError   # (the key alone is tested)

        def source_files(self):
            return [lib]
    key = Sim().cache_token()
    lib.write_bytes(b"version two")   # same size, another build
    assert Sim().cache_token() != key


# --- errors name the file --------------------------------------------------------------------------------

def test_a_full_disk_names_the_file_that_could_not_be_written(tmp_path):
    import errno

    from cross_checks.core.files import atomic_write

    def full(tmp):
        raise OSError(errno.ENOSPC, "No space left on device")
    target = tmp_path / "summary.json"
    with pytest.raises(OSError) as info:
        atomic_write(target, full)
    assert info.value.filename == str(target) and info.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []   # the temporary beside it is gone


def test_a_run_that_diverges_says_what_it_wrote(tmp_path, capsys):
    from cross_checks.scenario import catalog_path
    stiff = tmp_path / "stiff.toml"
    stiff.write_text(catalog_path("spring_oscillator").read_text()
                     .replace('name = "spring_oscillator"', 'name = "stiff"')
                     .replace("stiffness = ", "stiffness = 1e4 #"))
    out = tmp_path / "t.csv"
    assert main(["run", str(stiff), "--engine", "reference:explicit_euler",
                 "--dt", "0.05", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    import re
    assert ("diverged at t = " in err
            and re.search(r"wrote the initial state and the \d+ step\(s\) before it", err))
    assert out.is_file()


def test_a_report_drawing_in_a_directory_does_not_make_a_sweep_call_its_files_foreign(tmp_path):
    """While `rbcheck report DIR` draws, DIR holds its live staging folder and atomic temporaries; a sweep
    asked to replace DIR at that moment sees rbcheck's own files, not "files rbcheck did not write"."""
    from cross_checks.scenario import load_scenario
    from cross_checks.sweep import run_sweep
    from cross_checks.sweep.results_dir import check_output_dir, owned_name
    out = tmp_path / "res"
    run_sweep([load_scenario("projectile")], ["reference:course"],
              out, jobs=1, use_cache=False, progress=False)
    live = out / owned_name(".", "plots")   # this (live) process's drawing folder, as reports.render makes it
    live.mkdir()
    (live / "scenario-projectile-errors.png").write_bytes(b"png")
    (out / "rows").mkdir(exist_ok=True)
    (out / "rows" / ".projectile.csv.a1b2c3d4").write_text("temp")   # an atomic write in flight
    assert check_output_dir(str(out)) == out.resolve()


def test_check_refuses_a_step_beyond_the_limit(trajectory, capsys):
    assert main(["check", str(trajectory), "--scenario", "projectile", "--dt", "1e-300"]) == 2
    assert "--dt: 1e-300 s makes 1e+300 steps" in _one_line(capsys, "check")

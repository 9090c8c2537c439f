"""Every output path of every command is checked before any work; an output that cannot be written,
and every other error path, is exit 2 with one line (no traceback); time limits make failed rows."""
import time

import pytest

from cross_checks.cli import main
from cross_checks.scenario import catalog_path, parse_scenario
from tests.helpers.repo import BASELINE


@pytest.fixture
def regular_file(tmp_path):
    f = tmp_path / "file.txt"
    f.write_text("x")
    return f


def _one_line(capsys, command):
    err = capsys.readouterr().err
    assert err.startswith(f"rbcheck {command}: error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("where", ["under_file", "proc"])
def test_bench_json_fails_at_once_not_after_the_benchmark(regular_file, capsys, where):
    target = str(regular_file / "b.json") if where == "under_file" else "/proc/rbcheck-bench.json"
    t0 = time.perf_counter()
    assert main(["bench", "--quick", "--json", target]) == 2
    assert time.perf_counter() - t0 < 2.0  # the quick benchmark alone takes ~10 s
    _one_line(capsys, "bench")


@pytest.mark.parametrize("argv, command", [
    (["run", "projectile", "--engine", "reference:course", "--out", "{f}/t.csv"], "run"),
    (["run", "projectile", "--engine", "reference:course", "--out", "/proc/rbcheck-t.csv"], "run"),
    (["run", "projectile", "--engine", "reference:course", "--out", ""], "run"),
    (["compare", "{base}", "{base}", "--markdown", "{f}/d.md"], "compare"),
    (["compare", "{base}", "{base}", "--markdown", "/proc/rbcheck-d.md"], "compare"),
    (["sweep", "projectile", "--out", "{f}/res"], "sweep"),
    (["sweep", "projectile", "--out", "/proc/rbcheck-res"], "sweep"),
    (["report", "/proc"], "report"),
    (["report", "{f}"], "report"),
])
def test_unwritable_outputs_exit_2_in_one_line(regular_file, capsys, argv, command):
    base = str(BASELINE)
    assert main([a.format(f=regular_file, base=base) for a in argv]) == 2
    _one_line(capsys, command)


def test_a_write_that_fails_midway_is_one_line(monkeypatch, tmp_path, capsys):
    import errno

    import reports

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "index.html"))
    monkeypatch.setattr(reports, "render", full)
    (tmp_path / "res").mkdir()
    assert main(["report", str(tmp_path / "res")]) == 2
    assert "index.html: No space left on device" in _one_line(capsys, "report")


def test_an_unexpected_error_is_one_line_too(monkeypatch, capsys):
    import cross_checks.cli as cli

    def boom(args):
        raise RuntimeError("something rbcheck did not foresee\nsecond line")
    monkeypatch.setitem(cli.COMMANDS, "list", boom)
    assert main(["list"]) == 2
    assert "internal error: RuntimeError: something rbcheck did not foresee second line" in _one_line(capsys, "list")


def test_runs_and_references_over_their_time_limit_are_failed_rows(tmp_path, isolated_cache):
    from cross_checks.sweep import run_sweep
    slow_run = parse_scenario("""
name = "slow_run"
duration = 40.0
dt = 0.001
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
angular_velocity = [0.3, 1.0, 0.2]
""", "slow.toml")  # implicit Euler: ~110 us/step x 40000 steps ≈ 4 s ≫ 0.3 s
    stiff = parse_scenario(catalog_path("spring_pendulum").read_text().replace("stiffness = 40.0", "stiffness = 4e5")
                           .replace('name = "spring_pendulum"', 'name = "stiff"'), "stiff.toml")
    # Two sweeps, so that each limit is the only one that can trip: slow_run's own reference (DOP853 over
    # 40 s) may take longer than 0.3 s on a loaded machine, which is not what this test is about.
    t0 = time.perf_counter()
    summary = run_sweep([slow_run], ["reference:implicit_euler"], tmp_path / "res", jobs=1, use_cache=False,
                        progress=False, run_time_limit_s=0.3, reference_time_limit_s=600.0)
    summary_ref = run_sweep([stiff], ["reference:implicit_euler"], tmp_path / "res_ref", jobs=1, use_cache=False,
                            progress=False, run_time_limit_s=600.0, reference_time_limit_s=0.3)
    assert time.perf_counter() - t0 < 60
    import pandas as pd
    run_rows = pd.read_csv(tmp_path / "res" / "results.csv")
    ref_rows = pd.read_csv(tmp_path / "res_ref" / "results.csv")
    assert set(run_rows.status) == {"failed"}
    assert run_rows.message.str.contains("the run took longer than the time limit of 0.3 s").all()
    assert set(ref_rows.status) == {"failed"}
    assert ref_rows.message.str.contains("the reference solution took longer than the time limit of 0.3 s").all()
    assert summary["run"]["failed_runs"] == len(run_rows)
    assert summary_ref["run"]["failed_runs"] == len(ref_rows)

"""Every output path of every command is checked before any work; an output that cannot be written,
and every other error path, is exit 2 with one line (no traceback); time limits make failed rows."""
import json
import subprocess
import sys

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
    assert (err.startswith(f"rbcheck {command}: error: ")
            and err.count("\n") == 1 and "Traceback" not in err), err
    return err


@pytest.mark.parametrize("where", ["under_file", "proc"])
def test_bench_json_fails_at_once_not_after_the_benchmark(regular_file, capsys, monkeypatch, where):
    import cross_checks.bench

    def measured(*a, **k):
        raise AssertionError("the benchmark ran before its --json output was checked")
    monkeypatch.setattr(cross_checks.bench, "main", measured)
    target = str(regular_file / "b.json") if where == "under_file" else "/proc/rbcheck-bench.json"
    assert main(["bench", "--quick", "--json", target]) == 2
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
    assert ("internal error: RuntimeError: something rbcheck did not foresee second line"
            in _one_line(capsys, "list"))


def test_runs_and_references_over_their_time_limit_are_failed_rows(tmp_path, isolated_cache):
    slow_text = """
name = "slow_run"
duration = 200.0
dt = 0.001
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
angular_velocity = [0.3, 1.0, 0.2]
"""  # implicit Euler, compiled: ~0.5-5 us/step x 2e5 steps ≈ 0.1-1 s ≫ 0.05 s (the limit acts between chunks)
    stiff_text = (catalog_path("spring_pendulum").read_text().replace("stiffness = 40.0", "stiffness = 4e5")
                  .replace('name = "spring_pendulum"', 'name = "stiff"'))
    # Two sweeps, so that each limit is the only one that can trip: slow_run's own reference (DOP853 over
    # 200 s) may take longer than 0.05 s on a loaded machine, which is not what this test is about. Each in a
    # fresh interpreter: the limit is a SIGALRM timer of the main thread, and a test worker's state (after
    # hundreds of other tests) is not what a sweep process starts with.
    code = ("import json, sys\n"
            "from cross_checks.scenario import load_scenario\n"
            "from cross_checks.sweep import run_sweep\n"
            "s = run_sweep([load_scenario(sys.argv[1])], ['reference:implicit_euler'], sys.argv[2], jobs=1, "
            "use_cache=False, progress=False, run_time_limit_s=float(sys.argv[3]), "
            "reference_time_limit_s=float(sys.argv[4]))\nprint(json.dumps(s['run']['failed_runs']))")
    failed = {}
    for text, out, run_limit, ref_limit in ((slow_text, "res", 0.05, 600.0),
                                            (stiff_text, "res_ref", 600.0, 0.3)):
        parse_scenario(text, f"{out}.toml")  # valid, so that a failure below is about the limits
        toml = tmp_path / f"{out}.toml"
        toml.write_text(text)
        proc = subprocess.run([sys.executable, "-c", code, str(toml),
                               str(tmp_path / out), str(run_limit), str(ref_limit)],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr[-2000:]
        failed[out] = json.loads(proc.stdout.strip().splitlines()[-1])
    import pandas as pd
    run_rows = pd.read_csv(tmp_path / "res" / "results.csv")
    ref_rows = pd.read_csv(tmp_path / "res_ref" / "results.csv")
    assert set(run_rows.status) == {"failed"}
    assert run_rows.message.str.contains("the run took longer than the time limit of 0.05 s").all()
    assert set(ref_rows.status) == {"failed"}
    assert ref_rows.message.str.contains(
        "the reference solution took longer than the time limit of 0.3 s").all()
    assert failed == {"res": len(run_rows), "res_ref": len(ref_rows)}

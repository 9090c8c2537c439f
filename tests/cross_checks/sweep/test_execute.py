"""The references stage: the slowest solves start first, and each scenario still gets its own reference."""
import tomllib
from pathlib import Path

import cross_checks
from cross_checks.scenario import load_scenario
from cross_checks.sweep.execute import Runner, _reference_cost, run_references

CATALOG = Path(cross_checks.__file__).parent / "scenario" / "catalog"


def test_dop853_references_are_submitted_before_closed_forms():
    names = ["projectile", "spring_pendulum", "tennis_racket", "applied_torque"]
    order = sorted(names, key=lambda n: _reference_cost(load_scenario(n)))
    declared = {n: tomllib.loads((CATALOG / f"{n}.toml").read_text()).get("reference") for n in names}
    assert {declared[n] for n in order[:2]} == {"ground_truth"}  # as the scenario files say
    assert order[0] == "spring_pendulum"  # 5 s at 0.5 ms: the longer DOP853 grid of the two


def test_references_come_back_in_the_order_of_the_scenarios(tmp_path):
    scenarios = [load_scenario(n) for n in ("projectile", "applied_torque", "linear_drag")]
    refs = run_references(Runner(1), scenarios, tmp_path, None, False, None)
    assert [r.label.split(" ")[0] for r in refs] == ["analytic", "ground_truth", "analytic"]
    assert all(Path(r.path).is_file() and not r.error for r in refs)


def _square(x):
    return x * x


def test_items_are_read_as_work_is_submitted_at_most_a_window_in_flight():
    """A generator of items is asked for the next one only when a slot frees up, so it can stop on what it
    has seen (the fuzz's time budget): with one item in flight, it is asked exactly once per result."""
    done = []

    def items():
        i = 0
        while len(done) < 3:
            yield i
            i += 1
    runner = Runner(2)
    try:
        got = runner.map_unordered(_square, items(), lambda it, r: done.append(r), window=1)
    finally:
        runner.close()
    assert got == [(0, 0), (1, 1), (2, 4)]



_KILLED_MID_RESULT = """
import sys, threading, time
from cross_checks.sweep.execute import Runner

def big(i):   # a result much larger than a pipe's buffer: a worker is writing one most of the time
    return b"x" * 20_000_000

runner = Runner(4)
threading.Thread(target=lambda: runner.map_unordered(big, range(10 ** 6)), daemon=True).start()
time.sleep(float(sys.argv[1]))
runner.close(kill=True)
print("closed", flush=True)
"""


def test_a_pool_killed_while_a_worker_writes_a_large_result_lets_the_process_exit(tmp_path):
    """Runner.close(kill=True) kills workers mid-write; the pool's manager thread (which Python joins at
    exit) then waited for the rest of the message for ever: the process never exited. A hang is detected
    by the subprocess' timeout (60 s, against well under a second when it works)."""
    import subprocess
    import sys
    script = tmp_path / "killed.py"
    script.write_text(_KILLED_MID_RESULT)
    for delay in ("0.8", "1.5"):
        proc = subprocess.run([sys.executable, str(script), delay], capture_output=True, text=True,
                              timeout=60, cwd=Path(cross_checks.__file__).parents[1])
        assert proc.returncode == 0 and proc.stdout.strip() == "closed", proc.stderr

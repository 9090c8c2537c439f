"""Engine files (cross_checks.engines.external): every bad file is exit 2 with FILE: FIELD: REASON and
nothing written; every misbehaving command is a failed row carrying its own words (never a traceback);
a blow-up written by the engine is "diverged at t = …"; a hung command and everything it started are
killed at the time limit."""
import contextlib
import dataclasses
import io
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cross_checks import engines
from cross_checks.cli import main
from cross_checks.engines.base import EngineError
from cross_checks.engines.external import EngineFileError, load_engine_file
from cross_checks.scenario import parse_scenario
from cross_checks.sweep import run_sweep

TINY_TEXT = """
name = "tiny"
duration = 0.1
dt = 0.01
dt_ladder = [0.02, 0.01]
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
velocity = [1.0, 0.0, 0.0]
angular_velocity = [0.0, 0.0, 0.5]
"""
TINY = parse_scenario(TINY_TEXT, source="tiny.toml")

#: A misbehaving engine: argv[1] says how. It never imports rbcheck.
ENGINE_PY = r'''
import json, os, signal, subprocess, sys, time
mode, sj, out = sys.argv[1:4]
sc = json.load(open(sj))
n, dt, i = sc["steps"], sc["dt"], sc["initial"]
row0 = i["position"] + i["velocity"] + i["orientation"] + i["angular_velocity"]
rows = [[k * dt] + list(row0) for k in range(n + 1)]
HEADER = "t,x,y,z,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz"
def write(rows, path=out, header=HEADER):
    with open(path, "w") as fh:
        fh.write(header + "\n" + "".join(",".join(repr(v) for v in r) + "\n" for r in rows))
if mode == "ok": write(rows)
elif mode == "exit3": sys.stderr.write("mysim: inertia matrix is singular\n"); sys.exit(3)
elif mode == "segv": sys.stderr.write("about to crash\n"); sys.stderr.flush(); os.kill(os.getpid(), signal.SIGSEGV)
elif mode == "nothing": print("simulation finished (but where is the CSV?)")
elif mode == "garbage": open(out, "w").write("hello world\nthis is not a trajectory\n")
elif mode == "binary": open(out, "wb").write(b"\xff\xfe\x00garbage")
elif mode == "no_quaternion": write([r[:7] + r[11:] for r in rows], header="t,x,y,z,vx,vy,vz,wx,wy,wz")
elif mode == "short": write(rows[:4])
elif mode == "long": write(rows + [[(n + 1) * dt] + list(row0)])
elif mode == "offgrid": write([[2 * r[0]] + r[1:] for r in rows])
elif mode == "nan_first": rows[0][1] = float("nan"); write(rows)
elif mode == "nan_mid":
    for r in rows[6:]: r[1] = float("nan")
    write(rows)
elif mode == "blowup_mid": rows[4][5] = 3e9; write(rows)
elif mode == "escape":   # a child in a session of its own, left running after the command exits 0
    child = subprocess.Popen(["setsid", sys.executable, "-c", "import time; time.sleep(60)"])
    time.sleep(0.3)
    open(sys.argv[4], "w").write(" ".join(str(p) for p in (os.getpid(), child.pid)))
    write(rows)
elif mode == "chatty":   # prints without end until the time limit
    line = "x" * 1000 + "\n"
    while True: sys.stdout.write(line)
elif mode == "scratch": write(rows); open("scratch.tmp", "w").write("the engine's own scratch")
elif mode == "huge": open(out, "w").write(HEADER + "\n" + "1," * 2_000_000)
elif mode == "outside": write(rows); open("stray.csv", "w").write("oops")
elif mode == "elsewhere": write(rows, path="trajectory.csv")
elif mode == "wrong_start": rows[0][8] = 0.5; write(rows)
elif mode == "hang":
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    open(sys.argv[4], "w").write(f"{os.getpid()} {child.pid}")
    time.sleep(60)
    open(sys.argv[4] + ".finished", "w").write("the command ran to its end: it was not killed")
'''

MODES = ["ok", "exit3", "segv", "nothing", "garbage", "binary", "no_quaternion", "short", "long", "offgrid",
         "nan_first", "nan_mid", "blowup_mid", "huge", "outside", "elsewhere", "wrong_start", "scratch"]


def _engine_file(folder: Path, modes=MODES, name="fake", timeout=20, extra="") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "engine.py").write_text(ENGINE_PY)
    text = f'name = "{name}"\nversion = "0.1"\ntimeout = {timeout}\n{extra}\n'
    for m in modes:
        text += (f'[variants.{m}]\norder = 1\ndescription = "{m}"\n'
                 f'command = ["{sys.executable}", "engine.py", "{m}", "{{scenario_json}}", "{{out_csv}}"]\n')
    path = folder / "fake.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def fake(tmp_path_factory):
    return load_engine_file(_engine_file(tmp_path_factory.mktemp("fake")))


@pytest.fixture(autouse=True)
def _fresh_registry():
    yield
    engines.reset_registry()


# --- runs that fail, diverge or pass ----------------------------------------------------------------

@pytest.mark.parametrize("mode, words", [
    ("exit3", ["exited with status 3", "it said: mysim: inertia matrix is singular"]),
    ("segv", ["killed by signal SIGSEGV", "about to crash"]),
    ("nothing", ["exited 0 but wrote no CSV at {out_csv}", "where is the CSV?"]),
    ("garbage", ["the CSV is not a trajectory", "{out_csv}: header: no column 't'"]),
    ("binary", ["the CSV is not a trajectory", "cannot read"]),
    ("no_quaternion", ["orientation columns qw,qx,qy,qz missing"]),
    ("short", ["the CSV has 4 rows, expected 11 (t = 0 and each of the 10 steps)"]),
    ("long", ["the CSV has 12 rows, more than the 11"]),
    ("offgrid", ["row 1 (line 3) has t = 0.02, expected 0.01"]),
    ("nan_first", ["the first row (t = 0) is not a finite state"]),
    ("huge", ["bytes, more than 1024 bytes per row for 11 rows"]),
    ("elsewhere", ["wrote no CSV at {out_csv} but trajectory.csv in its working directory"]),
])
def test_a_misbehaving_command_fails_with_its_own_words(fake, mode, words):
    with pytest.raises(EngineError) as info:
        fake.simulate(TINY, mode, 0.01, 10)
    msg = str(info.value)
    assert msg.startswith(f"fake:{mode} at Δt = 0.01 s: ")
    for w in words:
        assert w in msg, msg
    assert not list(fake.folder.glob("*.csv"))   # a private working directory: nothing in the engine's folder
    for p in fake.folder.glob("*.csv"):
        p.unlink()  # what a misbehaving engine left behind must not fail the next test


@pytest.mark.parametrize("mode, k, what",
                         [("nan_mid", 6, "non-finite state"), ("blowup_mid", 4, "state beyond 1e+08")])
def test_a_blow_up_written_by_the_engine_is_a_divergence_at_its_time(fake, mode, k, what):
    run = fake.simulate(TINY, mode, 0.01, 10)
    assert run.diverged_at_s == pytest.approx(k * 0.01)
    assert run.message.startswith(f"diverged at t = {k * 0.01:.6g} s ({what}, written by the engine)")
    assert len(run.t_s) == k and run.y.shape == (k, 13)


def test_a_correct_run_keeps_the_rows_on_the_exact_grid_and_notes_a_wrong_start(fake):
    run = fake.simulate(TINY, "ok", 0.01, 10)
    assert run.diverged_at_s is None and run.message == ""
    assert run.t_s.tolist() == (0.01 * __import__("numpy").arange(11)).tolist()
    run = fake.simulate(TINY, "wrong_start", 0.01, 10)
    assert run.diverged_at_s is None
    assert "first row differs from the scenario's initial state (orientation by" in run.message


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split()[2]
    except OSError:
        return False
    return state not in ("Z", "X")


def test_a_hung_command_and_its_children_are_killed_at_the_time_limit(tmp_path):
    pids = tmp_path / "pids"
    path = _engine_file(tmp_path / "hang", modes=[], timeout=3)  # time enough to start on a loaded machine
    path.write_text(path.read_text() + f'[variants.hang]\norder = 1\ncommand = ["{sys.executable}", '
                                       '"engine.py", "hang", "{scenario_json}", "{out_csv}", '
                                       f'"{pids}"]\n')
    eng = load_engine_file(path)
    import time
    with pytest.raises(EngineError,
                       match=r"no result within the time limit of 3 s \(set `timeout` in fake.toml\)"):
        eng.simulate(TINY, "hang", 0.01, 10)
    # killed at the limit, not let run to its end (which writes the marker after its 60 s sleep)
    assert not Path(f"{pids}.finished").exists()
    for pid in map(int, pids.read_text().split()):
        deadline = time.monotonic() + 5.0  # SIGKILL to the group is delivered asynchronously
        while _alive(pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _alive(pid), f"process {pid} survived the time limit"


def test_a_program_deleted_after_loading_is_a_failed_run(tmp_path):
    folder = tmp_path / "gone"
    folder.mkdir()
    prog = folder / "sim.sh"
    prog.write_text("#!/bin/sh\nexit 0\n")
    prog.chmod(0o755)
    (folder / "e.toml").write_text('name = "gone"\n[variants.v]\norder = 1\ncommand = ["./sim.sh", '
                                   '"{scenario_json}", "{out_csv}"]\n')
    eng = load_engine_file(folder / "e.toml")
    prog.unlink()
    with pytest.raises(EngineError, match="cannot start .*sim.sh.*No such file"):
        eng.simulate(TINY, "v", 0.01, 10)


def test_failed_runs_are_rows_with_the_words_and_make_the_sweep_exit_1(tmp_path, isolated_cache):
    from cross_checks.cli.sweep import _gate_failures
    path = _engine_file(tmp_path / "eng", modes=["ok", "exit3"])
    with engines.engine_files_registered([path]):
        summary = run_sweep([TINY], ["fake:ok", "fake:exit3"], tmp_path / "r", jobs=2, progress=False)
    assert "2 run(s) failed (status 'failed' in results.csv)" in _gate_failures(summary)
    import csv
    rows = list(csv.DictReader(open(tmp_path / "r" / "results.csv")))
    failed = [r for r in rows if r["status"] == "failed"]
    assert {r["engine"] for r in failed} == {"fake:exit3"} and len(failed) == 2
    assert all("mysim: inertia matrix is singular" in r["message"] for r in failed)
    assert {r["status"] for r in rows if r["engine"] == "fake:ok"} == {"ok"}


def test_run_of_a_failing_engine_exits_1_with_its_words_and_writes_nothing(tmp_path, capsys):
    path = _engine_file(tmp_path / "eng", modes=["exit3"])
    out = tmp_path / "t.csv"
    assert main(["run", "projectile", "--engine", "fake:exit3",
                 "--engine-file", str(path), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert (err.count("\n") == 1 and "projectile with fake:exit3 failed" in err
            and "inertia matrix is singular" in err)
    assert not out.exists() and not out.with_suffix(".json").exists()


def test_sweep_records_the_engine_file_run_in_parallel_jobs(tmp_path, isolated_cache):
    """Runs of an engine file are ordinary jobs of the pool: workers that were not forked from the
    parent (e.g. Dask) receive the engine with the job and register it themselves."""
    path = _engine_file(tmp_path / "eng", modes=["ok"])
    with engines.engine_files_registered([path]):
        shipped = engines.user_engines()
    assert "fake" not in [e.name for e in engines.engine_entries()]
    engines.adopt_user_engines(shipped)  # what _run_job_item does in such a worker
    summary = run_sweep([TINY], ["fake:ok"], tmp_path / "r", jobs=2, progress=False)
    assert summary["run"]["runs"] == 2 and summary["run"]["failed_runs"] == 0


# --- bad engine files: exit 2, one line naming file, field and reason ---------------------------------

GOOD_VARIANT = ('[variants.v]\norder = 1\n'
                'command = ["{exe}", "engine.py", "ok", "{{scenario_json}}", "{{out_csv}}"]\n')

BAD_FILES = [
    ('version = "1"\n' + GOOD_VARIANT, "name", "missing (required)"),
    ('name = "My-Sim"\n' + GOOD_VARIANT, "name", "must match [a-z0-9_]+"),
    ('name = "mujoco"\n' + GOOD_VARIANT, "name", "is already an engine (entry point mujoco"),
    ('name = "reference"\n' + GOOD_VARIANT, "name", "is already an engine"),
    ('name = "x"\nverison = "1"\n' + GOOD_VARIANT, "verison", "unknown key (did you mean 'version'?)"),
    ('name = "x"\nversion = 0.3\n' + GOOD_VARIANT, "version",
     'must be a non-empty string, got 0.3 (quote it: version = "0.3")'),
    ('name = "x"\ntimeout = -1\n' + GOOD_VARIANT, "timeout", "must be a number of seconds in (0, 86400]"),
    ('name = "x"\n', "variants", "missing (required)"),
    ('name = "x"\nvariants = 3\n', "variants", "must contain at least one [variants.NAME] table"),
    ('name = "x"\n[variants.Euler]\norder = 1\ncommand = ["{exe}", "{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.Euler", "variant name must match"),
    ('name = "x"\n[variants]\nv = 3\n', "variants.v", "must be a table"),
    ('name = "x"\n[variants.v]\norder = 1\ncmd = []\n',
     "variants.v.cmd", "unknown key (did you mean 'command'?)"),
    ('name = "x"\n[variants.v]\ncommand = ["{exe}", "{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.v.order", "missing (required)"),
    ('name = "x"\n[variants.v]\norder = true\ncommand = ["{exe}", "{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.v.order", "must be a number in (0, 20], got True"),
    ('name = "x"\n[variants.v]\norder = "1"\ncommand = ["{exe}", "{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.v.order", "must be a number in (0, 20]"),
    ('name = "x"\n[variants.v]\norder = 0\ncommand = ["{exe}", "{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.v.order", "must be a number in (0, 20], got 0"),
    ('name = "x"\n[variants.v]\norder = 1\n', "variants.v.command", "missing (required)"),
    ('name = "x"\n[variants.v]\norder = 1\ncommand = "./sim {{scenario_json}} {{out_csv}}"\n',
     "variants.v.command", "must be a non-empty list of strings"),
    ('name = "x"\n[variants.v]\norder = 1\ncommand = []\n', "variants.v.command", "must be a non-empty list"),
    ('name = "x"\n[variants.v]\norder = 1\ncommand = ["{exe}", 3, "{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.v.command[1]", "must be a string, got 3"),
    ('name = "x"\n[variants.v]\norder = 1\ncommand = ["{exe}", "{{scenario}}", "{{out_csv}}"]\n',
     "variants.v.command[1]",
     "unknown placeholder {scenario} in '{scenario}'; placeholders: {scenario_json}, {dt}"),
    ('name = "x"\n[variants.v]\norder = 1\ncommand = ["{exe}", '
     '"{{dt:.3f}}", "{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.v.command[1]", "placeholder {dt} takes no format spec"),
    ('name = "x"\n[variants.v]\norder = 1\ncommand = ["{exe}", '
     '"--dt={{dt", "{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.v.command[1]", "bad placeholder syntax in '--dt={dt'"),
    ('name = "x"\n[variants.v]\norder = 1\ncommand = ["{exe}", "{{scenario_json}}"]\n', "variants.v.command",
     "never mentions {out_csv}: the command cannot know where to write the trajectory"),
    ('name = "x"\n[variants.v]\norder = 1\ncommand = ["{exe}", "{{out_csv}}"]\n', "variants.v.command",
     "never mentions {scenario_json}"),
    ('name = "x"\n[variants.v]\norder = 1\ncommand = ["{{dt}}", "{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.v.command[0]", "the program must be named literally"),
    ('name = "x"\n[variants.v]\norder = 1\ncommand = ["./nope", "{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.v.command[0]", "./nope: no such file (looked in"),
    ('name = "x"\n[variants.v]\norder = 1\ncommand = ["./engine.py", "{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.v.command[0]", "./engine.py: is not executable (chmod +x?)"),
    ('name = "x"\n[variants.v]\norder = 1\ncommand = ["no-such-program-rbcheck", '
     '"{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.v.command[0]", "'no-such-program-rbcheck': no such program on PATH"),
    ('name = "x"\n[variants.v\norder = 1\n', "", "TOML syntax error"),
    # a script name with a typo is found when the file is read, not by every run failing (issue 44, point 4)
    ('name = "x"\n[variants.v]\norder = 1\ncommand = ["{exe}", "enigne.py", "{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.v.command[1]", "enigne.py: no such file (looked in"),
    ('name = "x"\n[variants.v]\norder = 1\ncommand = ["{exe}", "enigne.py", "{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.v.command[1]", "did you mean 'engine.py'?"),
    ('name = "x"\n[variants.v]\norder = 1\ncommand = ["{exe}", "src/sim", "{{scenario_json}}", "{{out_csv}}"]\n',
     "variants.v.command[1]", "src/sim: no such file"),
    ('name = "x"\nbody_forms = ["com_ofset"]\n[variants.v]\norder = 1\ncommand = ["{exe}", "e.py"]\n',
     "body_forms", "must be a list of the body forms"),
    ('name = "x"\nbody_forms = [["com_offset"]]\n[variants.v]\norder = 1\ncommand = ["{exe}", "e.py"]\n',
     "body_forms", "must be a list of the body forms"),
]


@pytest.mark.parametrize("text, field, reason", BAD_FILES,
                         ids=[f"{f or 'toml'}-{i}" for i, (_, f, _) in enumerate(BAD_FILES)])
def test_a_bad_engine_file_exits_2_naming_file_field_and_reason(tmp_path, capsys, text, field, reason):
    folder = tmp_path / "eng"
    _engine_file(folder, modes=[])
    path = folder / "bad.toml"
    path.write_text(text.format(exe=sys.executable))
    out = tmp_path / "t.csv"
    code = main(["run", "projectile", "--engine", "x:v", "--engine-file", str(path), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    prefix = f"rbcheck run: error: {path}: {field + ': ' if field else ''}"
    assert err.startswith(prefix) and reason in err, err
    assert not out.exists()


def test_arguments_that_are_not_files_are_not_checked(tmp_path):
    """Options, modules, numbers and files that exist pass validation (only a named file that is missing is
    refused)."""
    folder = tmp_path / "eng"
    _engine_file(folder, modes=[])
    path = folder / "ok.toml"
    path.write_text(f'name = "x"\n[variants.v]\norder = 1\ncommand = ["{sys.executable}", "-m", "mysim.main", '
                    '"--gain=1.5", "0.5", "engine.py", "{engine_dir}/engine.py", "{scenario_json}", "{out_csv}"]\n')
    assert load_engine_file(path).name == "x"


@pytest.mark.parametrize("make, reason",
                         [(lambda p: None, "no such file"), (lambda p: p.mkdir(), "is a directory"),
                          (lambda p: p.write_bytes(b"name = \"\xff\"\n"), "is not UTF-8 text")])
def test_an_unreadable_engine_file_exits_2(tmp_path, capsys, make, reason):
    path = tmp_path / "e.toml"
    make(path)
    assert main(["sweep", "projectile", "--engine-file", str(path), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"rbcheck sweep: error: {path}: {reason}") and err.count("\n") == 1, err
    assert not (tmp_path / "r").exists()


def test_two_engine_files_with_one_name_exit_2(tmp_path, capsys):
    a = _engine_file(tmp_path / "a", modes=["ok"])
    b = _engine_file(tmp_path / "b", modes=["ok"])
    assert main(["list", "--engine-file", str(a), "--engine-file", str(b)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"rbcheck list: error: {b}: name: name 'fake' "
                          f"is already registered by engine file {a}")


def test_the_same_engine_file_twice_is_one_engine(tmp_path, capsys):
    a = _engine_file(tmp_path / "a", modes=["ok"])
    assert main(["list", "--engine-file", str(a), "--engine-file", str(a)]) == 0
    out = capsys.readouterr().out
    assert f"fake: from engine file {a}" in out and out.count("fake:ok ") == 1 and "(order 1)" in out


# --- property: no engine file, however damaged, gives a traceback ---------------------------------------

_PROGRAMS = [sys.executable, "./nope", "no-such-program-rbcheck", "./engine.py"]
_ARGS = st.lists(st.sampled_from(["engine.py", "ok", "exit3", "garbage", "short", "nan_mid",
                                  "{scenario_json}", "{out_csv}", "{dt}", "{steps}", "{duration}", "{bogus}",
                                  "{dt:.3f}", "{", "}}", "--x={dt}"]), max_size=6)


@st.composite
def engine_files(draw):
    lines = []
    name = draw(st.sampled_from(['"fuzz"', '"Fuzz"', '""', '"mujoco"', "3", None]))
    if name is not None:
        lines.append(f"name = {name}")
    for key, vals in (("version", ['"1.0"', "1.5", '""']), ("timeout", ["10", "0", "-2", '"x"']),
                      ("colour", ['"red"'])):
        if draw(st.booleans()) and draw(st.booleans()):
            lines.append(f"{key} = {draw(st.sampled_from(vals))}")
    for vname in draw(st.lists(st.sampled_from(["euler", "rk4", "Bad"]), max_size=2, unique=True)):
        lines.append(f"[variants.{vname}]")
        order = draw(st.sampled_from(["1", "2.5", "0", "-1", "true", '"1"', None]))
        if order is not None:
            lines.append(f"order = {order}")
        if draw(st.booleans()):
            lines.append('description = "d"')
        cmd = draw(st.one_of(st.none(), st.just('"./sim"'),
                             st.builds(lambda p, a: "[" + ", ".join(f'"{x}"' for x in [p] + a) + "]",
                                       st.sampled_from(_PROGRAMS), _ARGS)))
        if cmd is not None:
            lines.append(f"command = {cmd}")
    text = "\n".join(lines) + "\n"
    if draw(st.booleans()) and draw(st.booleans()):  # damage: cut the file somewhere
        text = text[:draw(st.integers(0, len(text)))]
    return text, draw(st.sampled_from(["euler", "rk4"]))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=engine_files())
def test_no_engine_file_gives_a_traceback_only_exit_2_or_a_failed_run(tmp_path, case):
    text, variant = case
    folder = tmp_path / "fz"
    _engine_file(folder, modes=[])
    path = folder / "fuzz.toml"
    path.write_text(text)
    tiny = tmp_path / "tiny.toml"
    tiny.write_text(TINY_TEXT)
    out = folder.parent / f"out-{abs(hash(text))}.csv"
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["run", str(tiny), "--engine", f"fuzz:{variant}",
                     "--engine-file", str(path), "--out", str(out)])
    engines.reset_registry()
    text_err = err.getvalue()
    assert "Traceback" not in text_err
    assert code in (0, 1, 2), (code, text_err)
    if code == 2:
        assert text_err.count("\n") == 1 and text_err.startswith("rbcheck run: error: "), text_err
        assert not out.exists()
    elif code == 1:
        assert "failed:" in text_err or "diverged" in text_err, text_err
    for stray in folder.glob("*.csv"):
        stray.unlink()



# --- runs contained and attributed truly (hardening, third round) --------------------------------------

def test_the_command_runs_in_a_private_directory_its_scratch_is_its_own(fake):
    """What the command writes in its working directory (a stray CSV, a scratch file) is its own and removed
    with the run; the engine's folder is left as it was and the run passes."""
    before = sorted(p.name for p in fake.folder.iterdir())
    for mode in ("outside", "scratch"):
        run = fake.simulate(TINY, mode, 0.01, 10)
        assert run.diverged_at_s is None and len(run.t_s) == 11
    assert sorted(p.name for p in fake.folder.iterdir()) == before


def test_a_file_another_process_writes_into_the_engine_folder_is_not_blamed_on_it(tmp_path):
    """The worked example swept from the engine's own folder with the sweep's log written there (the shell
    writes sweep.log while every run goes on): a correct engine passes."""
    import os
    import subprocess

    from tests.helpers.byo import build_cbody
    built = build_cbody(tmp_path / "c_engine")
    env = {**os.environ, "MPLBACKEND": "Agg", "RBCHECK_CACHE_DIR": str(tmp_path / "cache")}
    cmd = (f"{sys.executable} -m cross_checks.cli sweep tennis_racket applied_torque "
           "tumbling_box --engines cbody --engine-file cbody.toml --out ../res > sweep.log")
    proc = subprocess.run(["bash", "-c", cmd], cwd=built["good"].parent, env=env, capture_output=True,
                          text=True, timeout=600)
    log = (built["good"].parent / "sweep.log").read_text()
    assert proc.returncode == 0, log[-1500:] + proc.stderr[-1500:]
    assert "all " in log.splitlines()[-1] and "verdicts as expected" in log.splitlines()[-1]


def test_a_child_in_a_session_of_its_own_is_killed_with_the_run(tmp_path):
    import time
    pids = tmp_path / "pids"
    path = _engine_file(tmp_path / "esc", modes=[])
    path.write_text(path.read_text() + f'[variants.escape]\norder = 1\ncommand = ["{sys.executable}", '
                                       '"engine.py", "escape", "{scenario_json}", "{out_csv}", '
                                       f'"{pids}"]\n')
    run = load_engine_file(path).simulate(TINY, "escape", 0.01, 10)
    assert len(run.t_s) == 11
    child = int(pids.read_text().split()[1])
    deadline = time.monotonic() + 5.0   # SIGKILL is delivered asynchronously
    while _alive(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(child), "the child the command started with setsid outlived the run"


def test_a_command_that_prints_without_end_keeps_only_a_tail(tmp_path):
    # 1 s: the command prints megabytes by then (a line of 1,000 characters per write, without end), and
    # every second of the limit is a second of a core spent printing and reading
    path = _engine_file(tmp_path / "chatty", modes=["chatty"], timeout=1)
    with pytest.raises(EngineError) as info:
        load_engine_file(path).simulate(TINY, "chatty", 0.01, 10)
    msg = str(info.value)
    assert "no result within the time limit of 1 s" in msg and "it said: " in msg
    assert len(msg) < 1200   # the tail only (OUTPUT_TAIL_CHARS), however much it printed


def test_the_cache_key_covers_every_file_of_the_engine_folder(tmp_path):
    """A command that runs driver.py, which imports simcore.py beside it: editing
    simcore.py changes the key."""
    folder = tmp_path / "drv"
    path = _engine_file(folder, modes=["ok"])
    (folder / "simcore.py").write_text("GYRO_SIGN = -1\n")
    key = load_engine_file(path).cache_token()
    assert load_engine_file(path).cache_token() == key            # stable
    (folder / "simcore.py").write_text("GYRO_SIGN = +1\n")
    assert load_engine_file(path).cache_token() != key            # a broken helper module is a new engine
    (folder / "results").mkdir()
    (folder / "results" / ".rbcheck-results.json").write_text("{}")
    (folder / "results" / "results.csv").write_text("x")
    (folder / ".swp").write_text("editor")
    key2 = load_engine_file(path).cache_token()
    (folder / "results" / "results.csv").write_text("y")         # rbcheck's own results dir: not the engine
    assert load_engine_file(path).cache_token() == key2


def test_a_variant_declares_the_precision_its_steps_compute_in(tmp_path):
    """``precision = "float32"`` gives the variant float32's floors and ladder (docs/verdicts.md,
    "Precision"), and otherwise the cautious traits of a variant that declares none; float64 is the default;
    anything else is refused naming the field."""
    from cross_checks.engines.base import DEFAULT_TRAITS
    path = _engine_file(tmp_path / "a", modes=["ok"])
    text = path.read_text().replace('order = 1\n', 'order = 1\nprecision = "float32"\n')
    path.write_text(text)
    eng = load_engine_file(path)
    assert eng.variants["ok"].traits == dataclasses.replace(DEFAULT_TRAITS, precision="float32")
    assert load_engine_file(_engine_file(tmp_path / "b", modes=["ok"])).variants["ok"].traits is None
    path.write_text(text.replace('"float32"', '"float16"'))
    with pytest.raises(EngineFileError, match=r"variants\.ok\.precision: must be one of float64, float32"):
        load_engine_file(path)


def test_a_variant_declares_its_invariance_findings(tmp_path):
    """``[[variants.NAME.invariance_findings]]`` (transform, within = { SIZE = [low, high] }, quantities,
    reason) become the variant's Traits.invariance_findings (docs/invariance.md, "Declared findings"); a bad
    entry is refused naming its field."""
    path = _engine_file(tmp_path / "a", modes=["ok"])
    entry = ('[[variants.ok.invariance_findings]]\ntransform = "translation"\n'
             'within = { distance_m = [1e3, 1e4] }\nquantities = ["position"]\nreason = "far out"\n')
    path.write_text(path.read_text() + entry)
    (f,) = load_engine_file(path).variants["ok"].traits.invariance_findings
    assert (f.transform, f.within, f.quantities, f.reason) == ("translation", (("distance_m", 1e3, 1e4),),
                                                               ("position",), "far out")
    bad = [('transform = "translation"', 'transform = "shift"', r"invariance_findings\[0\]\.transform: must be"),
           ("within = { distance_m = [1e3, 1e4] }", "within = {}", r"\[0\]\.within: must bound at least one"),
           ("distance_m = [1e3, 1e4]", "k = [1e3, 1e4]", r"\[0\]\.within\.k: must be a size of translation"),
           ("[1e3, 1e4]", "[1e4, 1e3]", r"\[0\]\.within\.distance_m: .*low <= high"),
           ('["position"]', '["place"]', r"\[0\]\.quantities: must be a non-empty list"),
           ('reason = "far out"', 'reason = ""', r"\[0\]\.reason: missing \(required\)"),
           ('reason = "far out"', 'reason = "far out"\nowner = "me"', r"\[0\]\.owner")]
    for old, new, words in bad:
        path.write_text(path.read_text().replace(entry, entry.replace(old, new)))
        with pytest.raises(EngineFileError, match=words):
            load_engine_file(path)
        path.write_text(path.read_text().replace(entry.replace(old, new), entry))


# --- what outlives rbcheck (issue 45) -------------------------------------------------------------------------

#: A process that runs an engine file's hanging command as a pool worker would (SIGTERM at its default; the
#: command writes its pid and its child's into PIDS). argv: engine file, pids file.
_WORKER = """
import signal, sys
signal.signal(signal.SIGTERM, signal.SIG_DFL)
from cross_checks.engines.external import load_engine_file
from cross_checks.scenario import parse_scenario
sc = parse_scenario('''{scenario}''', source="tiny.toml")
load_engine_file(sys.argv[1]).simulate(sc, "hang", 0.01, 10)
"""


def _worker_running_a_hung_command(tmp_path):
    import os
    import subprocess
    import time
    pids = tmp_path / "pids"
    path = _engine_file(tmp_path / "hang", modes=[], timeout=300)
    path.write_text(path.read_text() + f'[variants.hang]\norder = 1\ncommand = ["{sys.executable}", '
                                       '"engine.py", "hang", "{scenario_json}", "{out_csv}", '
                                       f'"{pids}"]\n')
    (tmp_path / "tmp").mkdir()
    env = {**os.environ, "TMPDIR": str(tmp_path / "tmp")}
    worker = subprocess.Popen([sys.executable, "-c", _WORKER.format(scenario=TINY_TEXT), str(path)], env=env,
                              cwd=Path(engines.__file__).parents[2], start_new_session=True)
    deadline = time.monotonic() + 120
    while not (pids.exists() and len(pids.read_text().split()) == 2) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert list((tmp_path / "tmp").glob("rbcheck-fake-*")), "the run's private directory"
    return worker, [int(p) for p in pids.read_text().split()]


def _all_gone(pids):
    import time
    deadline = time.monotonic() + 10.0   # the death signals are delivered asynchronously
    while any(_alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    return [p for p in pids if _alive(p)]


def test_an_engine_command_dies_with_a_worker_killed_by_sigkill(tmp_path):
    """``kill -9`` of the sweep's process group (timeout -s KILL, a CI cancel, the OOM killer) left the command
    and its child running, re-parented to init, with no time limit, and their private directory."""
    import os
    import signal
    import time
    worker, pids = _worker_running_a_hung_command(tmp_path)
    os.killpg(worker.pid, signal.SIGKILL)   # the command runs in a session of its own: not in this group
    worker.wait()
    assert _all_gone(pids) == [], "the engine command outlived rbcheck"
    deadline = time.monotonic() + 10.0   # removed by the supervisor as it goes
    while list((tmp_path / "tmp").iterdir()) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert list((tmp_path / "tmp").iterdir()) == [], "the run's private directory outlived rbcheck"


def test_a_worker_stopped_by_sigterm_removes_the_run_s_private_directory(tmp_path):
    import os
    import signal
    worker, pids = _worker_running_a_hung_command(tmp_path)
    os.kill(worker.pid, signal.SIGTERM)   # how a sweep stops its workers after Ctrl-C or SIGTERM
    worker.wait(timeout=60)
    assert _all_gone(pids) == []
    assert list((tmp_path / "tmp").iterdir()) == []

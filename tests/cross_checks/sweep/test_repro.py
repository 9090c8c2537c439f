"""cross_checks.sweep.repro: the claim parser, and reproducers that run without rbcheck, exit 1 while the
defect holds and 0 when it does not, and decide as rbcheck did when it wrote them."""
import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from cross_checks.scenario import load_scenario
from cross_checks.sweep.repro import ENGINES, ReproError, file_name, parse_claim, reproducer, write_reproducer

pytest.importorskip("mujoco")

#: what a reproducer must never import
RBCHECK = ("rbcheck", "cross_checks", "reference_sim", "reports", "tests")

#: Runs the script with rbcheck's packages unimportable (None in sys.modules makes `import X` fail), from a
#: folder outside the repository and with no PYTHONPATH: rbcheck is installed in this venv, so this is how
#: a script that needed it would fail here.
BLOCKED = ("import runpy, sys\n"
           + "".join(f"sys.modules[{m!r}] = None\n" for m in RBCHECK)
           + "sys.argv = [sys.argv[1]]\nrunpy.run_path(sys.argv[0], run_name='__main__')\n")


@pytest.mark.parametrize("words,says", [
    ([], "give a claim"),
    (["flip"], "unknown claim 'flip'"),
    (["order"], "give one QUANTITY"),
    (["order", "speed"], "unknown quantity 'speed'"),
    (["order", "orientation", "position"], "give one QUANTITY"),
    (["drift", "fast"], "takes no word"),
    (["invariance"], "give a TRANSFORM"),
    (["invariance", "spin"], "unknown transform 'spin'; known: translation 10 m; translation 1e+03 m"),
    (["invariance", "scale", "k=0.5"], "unknown transform 'scale k=0.5'; known: "),
    (["invariance", "translation"], "invariance translation: give its magnitude"),
])
def test_a_bad_claim_is_one_line_naming_what_is_wrong(words, says):
    with pytest.raises(ReproError, match=re.escape(says)) as e:
        parse_claim(words)
    assert "\n" not in str(e.value)


def test_claims_parse():
    assert parse_claim(["order", "orientation"]) == ("order", "orientation")
    assert parse_claim(["drift"]) == ("drift", "")
    # the transform as invariance.csv names it (transform, magnitude), its numbers in any spelling
    assert parse_claim(["invariance", "translation", "1e4"]) == ("invariance", "translation 1e+04 m")
    assert parse_claim(["invariance", "scale k=0.01 mu=0.01"]) == ("invariance", "scale k=0.01 mu=0.01")
    assert parse_claim(["invariance", "rotation"]) == ("invariance", "rotation 135 deg")


@pytest.mark.parametrize("variant,scenario,claim,says", [
    ("mujoco:rk4", "tennis_racket", ["invariance", "rotated"], "unknown transform 'rotated'"),
    ("pybullet:maximal", "tennis_racket", ["invariance", "welded_split"], "cannot express welded_split"),
    ("pybullet:multibody", "tumbling_box", ["invariance", "welded_split"], "cannot express welded_split"),
    ("mujoco:euler", "long_major_axis_spin", ["invariance", "rotation"], "does not transform long runs"),
    ("reference:rk4", "tennis_racket", ["order", "orientation"], "reference is rbcheck's own"),
    ("mujoco:rk4", "spring_pendulum", ["order", "orientation"], "forces change with the state"),
    ("mujoco:rk4", "projectile", ["gyroscopic"], "does not flip"),
    ("mujoco:rk4", "long_major_axis_spin", ["order", "orientation"], "is a long run"),
])
def test_what_a_reproducer_cannot_state_is_refused_in_one_line(variant, scenario, claim, says):
    with pytest.raises(ReproError, match=says):
        reproducer(variant, load_scenario(scenario), claim)


def _run_alone(path, tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONSTARTUP")}
    return subprocess.run([sys.executable, "-c", BLOCKED, str(path)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)


def _imports(text):
    out = set()
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            out.add((node.module or "").split(".")[0])
    return out


@pytest.mark.parametrize("variant,scenario,claim,holds", [
    ("mujoco:rk4", "tennis_racket", ["order", "orientation"], False),       # MuJoCo 4.0's RK4: order 4
    ("mujoco:implicit", "long_tennis_racket", ["drift"], True),            # the tumble becomes a spin
])
def test_a_reproducer_runs_without_rbcheck_and_exits_as_rbcheck_decided(variant, scenario, claim, holds,
                                                                       tmp_path):
    r = reproducer(variant, load_scenario(scenario), claim)
    assert r.holds is holds
    assert _imports(r.text) <= {"numpy", "mujoco", "sys", "importlib", "platform"}
    for name in RBCHECK[:3]:
        assert f"import {name}" not in r.text and f"from {name}" not in r.text
    path = write_reproducer(r, tmp_path / file_name(variant, scenario, " ".join(claim)))
    done = _run_alone(path, tmp_path)
    assert done.returncode == int(holds), done.stderr
    last = done.stdout.strip().splitlines()[-1]
    assert last == r.summary   # the same numbers here and there
    assert last.endswith("DEFECT" if holds else "no defect")
    first = done.stdout.splitlines()[0]
    assert first.startswith("mujoco ") and "numpy" in first and "Python" in first


def test_rapiers_drift_on_a_stable_major_axis_spin_holds_in_a_script_without_rbcheck(tmp_path):
    pytest.importorskip("rapier3d")
    r = reproducer("rapier:symplectic_euler", load_scenario("long_major_axis_spin"), ["drift"])
    assert r.holds and "toward the intermediate axis" in r.summary
    assert "mujoco" not in _imports(r.text) and "rapier3d" in _imports(r.text)
    done = _run_alone(write_reproducer(r, tmp_path / "rapier_drift.py"), tmp_path)
    assert done.returncode == 1, done.stderr
    assert done.stdout.strip().splitlines()[-1] == r.summary


def test_the_scripts_code_is_rbchecks_own_line_for_line():
    """Compacted, not rewritten: every code line of the script is a line of the world or the measurement
    (docstrings and comments left out; one indentation level out where the slice kept one branch of an
    `if`, cross_checks/sweep/repro_slice.py), and the world's definitions the run needs are all there."""
    import inspect

    from cross_checks.engines.worlds import mujoco as mjw
    from cross_checks.sweep import repro_measure
    r = reproducer("mujoco:rk4", load_scenario("tennis_racket"), ["order", "orientation"], run=False)
    ours = set(inspect.getsource(mjw).splitlines()) | set(inspect.getsource(repro_measure).splitlines())
    ours |= {re.sub(r"\s+#.*$", "", line) for line in ours}   # a line's trailing comment cut off
    ours = {line.strip() for line in ours}
    code = r.text[r.text.index('"""\n', 3) + 4:r.text.index("# the scenario")]
    lines = [line.strip() for line in code.splitlines()
             if line.strip() and not line.startswith(("import ", "from "))]
    assert lines and [line for line in lines if line not in ours] == []
    assert '"""' not in code and "#" not in code
    for name in ("def build_model(", "class Bodies:", "def world(", "def to_qpos_qvel(", "def main_order("):
        assert name in code
    assert "def apply_body_torque(" not in code and "def main_drift(" not in code   # never reached


def test_a_mujoco_order_script_is_short_and_prints_what_the_uncompacted_code_prints(tmp_path):
    """Issue 47: short enough to paste into an issue (REPRO_MUJOCO_ORDER_MAX_LINES, tests/helpers/
    tolerances.py); and the compacted script, run without rbcheck, prints exactly what rbcheck's modules
    print run whole on its numbers (the script before compaction was those modules' text)."""
    import contextlib
    import io

    from cross_checks.engines.worlds import mujoco as mjw
    from cross_checks.sweep import repro_measure
    from tests.helpers import tolerances as tol
    r = reproducer("mujoco:rk4", load_scenario("tennis_racket"), ["order", "orientation"], run=False)
    assert len(r.text.splitlines()) <= tol.REPRO_MUJOCO_ORDER_MAX_LINES
    ns = {"__name__": "not_main"}
    exec(compile(r.text, "repro", "exec"), ns)   # noqa: S102 - the numbers the script holds
    numbers = {k: v for k, v in ns.items() if k.isupper()}
    whole = io.StringIO()
    with contextlib.redirect_stdout(whole):
        code = repro_measure.main_order(mjw.world, numbers)
    done = _run_alone(write_reproducer(r, tmp_path / "rk4.py"), tmp_path)
    assert done.returncode == code, done.stderr
    assert done.stdout == whole.getvalue()
    assert "orientation order: measured 4.00" in done.stdout


#: the module each engine's script imports
_ENGINE_MODULE = {"drake": "pydrake", "dart": "dartpy"}


#: (variant, scenario, transform, holds) of test_an_invariance_script_judges_as_the_sweep_does_without_rbcheck
_INVARIANCE_SCRIPT_CASES = [
    ("mujoco:euler", "tennis_racket", ["rotation", "135", "deg"], False),
    ("pybullet:maximal", "tennis_racket", ["scale", "k=0.01", "mu=0.01"], True),   # solve33 threshold
    # a body off its COM, and of welded parts (MuJoCo #3553's class): MuJoCo's RK4 holds under both
    ("mujoco:rk4", "tennis_racket", ["com_offset"], False),
    ("mujoco:rk4", "tennis_racket", ["welded_split"], False),
    # Drake's implicit Euler steps the body origin: off the COM on the near-separatrix box its deviation
    # does not vanish at order 0.7 at the second halving (drake_engine.ORIGIN_STEP_FINDING, declared)
    pytest.param("drake:implicit_euler", "tumbling_box", ["com_offset", "1.5"], True,
                 marks=pytest.mark.first),   # one of the longest tests (tests/conftest.py)
    ("dart:semi_implicit_euler", "tennis_racket", ["welded_split"], False),
]


@pytest.mark.parametrize("variant,scenario,transform,holds", _INVARIANCE_SCRIPT_CASES)
def test_an_invariance_script_judges_as_the_sweep_does_without_rbcheck(variant, scenario, transform, holds,
                                                                      tmp_path):
    """The original and the transformed run (the transformed numbers from transforms.apply), mapped back,
    each quantity's largest deviation beside the sweep's allowance; exit 1 where the sweep says broken."""
    engine = variant.split(":")[0]
    module = _ENGINE_MODULE.get(engine, engine)
    pytest.importorskip(module)
    from cross_checks.core.quantities import COLUMN_STEM, QUANTITIES
    from cross_checks.sweep.invariance import check_invariance
    from cross_checks.sweep.repro import _transform
    sc = load_scenario(scenario)
    # run here too (rbcheck's own `repro`), but Drake's implicit Euler (a third of this test's 22 CPU s; the
    # same script text as the others', which run here)
    here = engine != "drake"
    r = reproducer(variant, sc, ["invariance", *transform], run=here)
    assert r.holds is (holds if here else None)
    assert _imports(r.text) <= {"numpy", module, "sys", "importlib", "platform", "math"}
    done = _run_alone(write_reproducer(r, tmp_path / "inv.py"), tmp_path)
    assert done.returncode == int(holds), done.stderr
    summary = done.stdout.strip().splitlines()[-1]
    assert summary == r.summary or not here
    from cross_checks.engines import resolve
    row = check_invariance(sc, resolve(variant), [_transform(transform)])[0]
    # a break the engine declares (PyBullet maximal's small body, Drake's origin step: Traits.
    # invariance_findings) is the sweep's `known finding`, not a failure of the sweep; to its maintainers
    # the script still says broken, exit 1
    assert row["verdict"] == ("known finding" if holds else "holds")
    assert summary.split(": ")[1].startswith("broken" if holds else "holds")
    if holds:   # a broken one's deviations are the model's, not round-off: the sweep's numbers
        for q in QUANTITIES:
            assert f"{q} largest deviation {row[COLUMN_STEM[q] + '_dev']:.3g}" in done.stdout


#: What a reproducer's form_world is planted with, per transform: the conversion between the COM and the body
#: origin with the velocity's ω × R c left out both ways (the origin then starts with the COM's velocity: a
#: different motion); the welded child's frame 5 cm off the body frame, its COM given from the wrong origin
#: (welded_split keeps the composite COM at the origin, so the conversion alone would not show).
_PLANTED = {"com_offset": (("y_o[..., 3:6] + np.cross(y_o[..., 10:13], r_W)", "y_o[..., 3:6]"),
                           ("y[..., 3:6] - np.cross(y[..., 10:13], r_W)", "y[..., 3:6]")),
            "welded_split": (("child.pos = [0.0, 0.0, 0.0]", "child.pos = [0.0, 0.0, 0.05]"),)}


@pytest.mark.parametrize("transform", sorted(_PLANTED))
def test_a_form_world_planted_wrong_is_broken_in_its_script(transform, tmp_path):
    """The script's form_world converts the state between the COM and the body origin with worlds/com.py's
    code and builds the welded parts as the adapter does (its code): planted wrong in the script, the
    transformed run is another motion, and the script, run without rbcheck, says broken and exits 1."""
    r = reproducer("mujoco:rk4", load_scenario("tennis_racket"), ["invariance", transform], run=False)
    text = r.text
    for good, bad in _PLANTED[transform]:
        assert text.count(good) == 1
        text = text.replace(good, bad)
    done = _run_alone(write_reproducer(type(r)(text, None, "", r.claim), tmp_path / "planted.py"), tmp_path)
    assert done.returncode == 1, done.stdout + done.stderr
    last = done.stdout.strip().splitlines()[-1]
    assert f"under {r.claim.removeprefix('invariance ')}: broken" in last and last.endswith("DEFECT")
    # as written, the same script (the same text with or without rbcheck's own run) holds and exits 0:
    # test_an_invariance_script_judges_as_the_sweep_does_without_rbcheck[mujoco:rk4-tennis_racket-...] runs
    # it (running it here too cost a second MuJoCo script per transform)
    assert ["mujoco:rk4", "tennis_racket", [transform], False] in [list(c) for c in _INVARIANCE_SCRIPT_CASES]


def test_an_engine_whose_world_cannot_build_the_form_is_refused_in_one_line(monkeypatch):
    """An adapter that builds a body off its COM while its world has no form_world (a reproducer would run
    another body): refused, naming the engines whose worlds can."""
    from cross_checks.sweep import repro
    monkeypatch.setattr(repro, "_has_form_world", lambda engine: engine != "mujoco")
    with pytest.raises(ReproError, match="mujoco's world cannot build a body off its COM .* these can: "
                                         "rapier, pybullet") as e:
        reproducer("mujoco:rk4", load_scenario("tennis_racket"), ["invariance", "com_offset"], run=False)
    assert "\n" not in str(e.value)


def test_findings_claims_states_each_finding_once_with_the_preferred_quantity():
    from cross_checks.sweep.repro import findings_claims
    sc, lr = load_scenario("tennis_racket"), load_scenario("long_major_axis_spin")
    rec = {"scenario": "tennis_racket", "matches_expectation": True, "expected_verdict": "converges"}
    summary = {"convergence": [
        {**rec, "engine": "mujoco:rk4", "quantity": "position", "matches_expectation": False},
        {**rec, "engine": "mujoco:rk4", "quantity": "orientation", "matches_expectation": False},
        {**rec, "engine": "rapier:symplectic_euler_no_gyro", "quantity": "orientation",
         "expected_verdict": "does_not_converge"},
        {**rec, "engine": "reference:course", "quantity": "orientation",
         "expected_verdict": "does_not_converge"},
        {**rec, "engine": "mujoco:euler", "quantity": "orientation", "expected_order": 1.0},
        {**rec, "engine": "mjx:rk4", "quantity": "position", "expected_order": 4.0},
        {**rec, "engine": "mjx:rk4", "quantity": "orientation", "expected_order": 2.0}],   # known shortfall
        "variants": [{"name": "mujoco:euler", "declared_order": 1.0},
                     {"name": "mjx:rk4", "declared_order": 4.0}],
        "long_runs": [{"engine": "rapier:symplectic_euler", "scenario": "long_major_axis_spin",
                       "finding": "drifts toward the intermediate axis", "status": "ok"},
                      {"engine": "mujoco:rk4", "scenario": "long_major_axis_spin", "finding": "",
                       "status": "ok"}],
        "invariance": [{"engine": "pybullet:maximal", "scenario": "tennis_racket", "transform": "scale",
                        "magnitude": "k=0.01 mu=0.01", "verdict": "broken"},
                       {"engine": "mujoco:euler", "scenario": "tennis_racket", "transform": "com_offset",
                        "magnitude": "1.5 gyration radii", "verdict": "step-dependent"}]}
    got = [(v, s.name, c) for v, s, c in findings_claims(summary, [sc, lr])]
    assert got == [("mujoco:rk4", "tennis_racket", ["order", "orientation"]),
                   ("rapier:symplectic_euler_no_gyro", "tennis_racket", ["gyroscopic"]),
                   ("mjx:rk4", "tennis_racket", ["order", "orientation"]),
                   ("rapier:symplectic_euler", "long_major_axis_spin", ["drift"]),
                   ("pybullet:maximal", "tennis_racket", ["invariance", "scale", "k=0.01", "mu=0.01"])]


def test_the_sweep_writes_each_findings_reproducer_and_the_report_links_it(tmp_path, monkeypatch):
    import json

    from cross_checks.cli import main
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
    out = tmp_path / "sweep"
    main(["sweep", "long_tennis_racket", "--engines", "mujoco:implicit", "--jobs", "1", "--out", str(out)])
    recs = json.loads((out / "summary.json").read_text())["reproducers"]
    assert recs == [{"engine": "mujoco:implicit", "scenario": "long_tennis_racket", "claim": "drift",
                     "file": "repro/mujoco_implicit__long_tennis_racket__drift.py"}]
    page = (out / "integrators.html").read_text()
    assert 'href="repro/mujoco_implicit__long_tennis_racket__drift.py"' in page
    done = _run_alone(out / recs[0]["file"], tmp_path)
    assert done.returncode == 1 and done.stdout.strip().endswith("DEFECT"), done.stdout + done.stderr


#: docs/findings/scripts/: the scripts rbcheck cannot write yet (their engine is not in repro.ENGINES), which
#: stay hand-written until it can (none: every built-in engine writes reproducers; a script that shows a
#: mechanism rather than a claim lives in docs/findings/mechanisms/).
HAND_WRITTEN: dict = {}
ROOT = Path(__file__).resolve().parents[3]
FINDINGS_SCRIPTS = sorted((ROOT / "docs" / "findings" / "scripts").glob("*.py"))
#: the module a reproducer's distribution imports as (to skip an engine that is not installed here)
_IMPORTS = {"rapier3d": "rapier3d", "sapien": "sapien", "dartpy": "dartpy", "mujoco-mjx": "mujoco.mjx"}


@pytest.mark.parametrize("path", FINDINGS_SCRIPTS, ids=lambda p: p.name)
def test_each_findings_script_is_exactly_what_rbcheck_repro_writes(path):
    """Issue 47: a finding's script is the reproducer `rbcheck repro` writes now, not a hand-written one that
    can drift from the adapter (regenerate it with the command in its first lines); a script whose engine
    cannot write reproducers yet is listed in HAND_WRITTEN and must not be able to."""
    import importlib.util
    import shlex

    from cross_checks.sweep.repro import ENGINES
    text = path.read_text(encoding="utf-8")
    if path.name in HAND_WRITTEN:
        assert HAND_WRITTEN[path.name] not in ENGINES, (
            f"{HAND_WRITTEN[path.name]} can write reproducers now: regenerate {path.name} with rbcheck repro")
        return
    m = re.search(r"\(rbcheck repro (\S+) (\S+) --claim ([^)]+)\)", text)
    assert m, f"{path.name} was not written by rbcheck repro (its header names the command)"
    variant, scenario, claim = m.group(1), m.group(2), shlex.split(m.group(3))
    for dist in ENGINES[variant.split(":")[0]][0]:
        if importlib.util.find_spec(_IMPORTS.get(dist, dist).split(".")[0]) is None:
            pytest.skip(f"{dist} is not installed here")
    now = reproducer(variant, load_scenario(scenario), claim, run=False).text
    assert text == now, (f"{path.name} differs from what rbcheck writes now: rbcheck repro {variant} "
                         f"{scenario} --claim {m.group(3)} --out {path.relative_to(ROOT)}")


def test_a_sweeps_com_offset_finding_gets_a_reproducer_not_a_note(tmp_path):
    """The sweep's invariance row of a body off its COM (Drake implicit Euler's declared finding on
    tumbling_box, as summary.json holds it) is written into DIR/repro/ like any other, the script's world
    form_world (before: a note saying a reproducer could not write the body)."""
    pytest.importorskip("pydrake")
    from cross_checks.sweep.repro import write_sweep_reproducers
    summary = {"invariance": [{"engine": "drake:implicit_euler", "scenario": "tumbling_box",
                               "transform": "com_offset", "magnitude": "1.5 gyration radii",
                               "verdict": "known finding"}]}
    recs = write_sweep_reproducers(tmp_path, summary, [load_scenario("tumbling_box")])
    name = "repro/drake_implicit_euler__tumbling_box__invariance_com_offset_1_5_gyration_radii.py"
    assert recs == [{"engine": "drake:implicit_euler", "scenario": "tumbling_box",
                     "claim": "invariance com_offset 1.5 gyration radii", "file": name}]
    text = (tmp_path / name).read_text()
    assert "sys.exit(main_invariance(form_world, globals()))" in text and "def com_state(" in text


def test_a_sweeps_broken_invariance_gets_its_reproducer_and_the_report_links_it(tmp_path, monkeypatch):
    """PyBullet's maximal coordinates at k = μ = 0.01 (docs/invariance.md, "In CI"): the sweep writes the
    invariance claim's script into DIR/repro/, the report links the finding to it, and the script, run
    without rbcheck, exits 1 as the sweep did."""
    import json

    from cross_checks.cli import main
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
    out = tmp_path / "sweep"
    assert main(["sweep", "tennis_racket", "--engines", "pybullet:maximal", "--invariance", "--no-long",
                 "--jobs", "1", "--out", str(out)]) == 0   # a declared known finding: said, not a failure
    recs = json.loads((out / "summary.json").read_text())["reproducers"]
    name = "repro/pybullet_maximal__tennis_racket__invariance_scale_k_0_01_mu_0_01.py"
    assert recs == [{"engine": "pybullet:maximal", "scenario": "tennis_racket",
                     "claim": "invariance scale k=0.01 mu=0.01", "file": name}]
    assert f'href="{name}"' in (out / "index.html").read_text()
    done = _run_alone(out / name, tmp_path)
    assert done.returncode == 1 and "under scale k=0.01 mu=0.01: broken" in done.stdout, done.stderr


def test_compacting_keeps_what_runs_and_leaves_out_what_does_not():
    """repro_text.compact on a planted module: docstrings and comments out (a '#' or a blank line inside a
    multi-line string kept), unreached and shadowed definitions out, methods only as reached, imports once at
    the top (standard library first), and the result runs."""
    from cross_checks.sweep.repro_text import compact
    first = ('"""Module doc."""\nimport math\nimport numpy as np\n\nUNUSED = 3\nK = 2.0  # a constant\n\n\n'
             'def helper(x):\n    """Doc."""\n    # drop me\n    return float(np.float64(x) * K)\n\n\n'
             'def world():\n    return "first"\n\n\n'
             'class Thing:\n    """Doc."""\n    def __init__(self):\n        self.v = helper(1.0)\n\n'
             '    def used(self):\n        return f"""{self.v}\n\n# not a comment"""\n\n'
             '    def unused(self):\n        return math.pi\n')
    second = "from .first import helper\nimport sys\n\n\ndef world():\n    return sys.version and Thing()\n"
    code = compact([first, second], 'print(world().used())\n')
    assert code.startswith("import sys\nimport numpy as np\n\nK = 2.0\n")   # math went with `unused`
    assert "Doc" not in code and "drop me" not in code and "from .first" not in code
    assert "UNUSED" not in code and "def unused" not in code and '"first"' not in code
    assert "\n\n# not a comment" in code
    import contextlib
    import io
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "compacted", "exec"), {"__name__": "x"})   # noqa: S102
    assert out.getvalue() == "2.0\n\n# not a comment\n"


#: the engine modules a reproducer of each engine may import, and the module whose absence skips it
_ENGINE_IMPORTS = {"newton": ({"warp", "newton", "mujoco", "warnings"}, "newton"),
                   "genesis": ({"genesis"}, "genesis")}


@pytest.mark.parametrize("variant,scenario,claim,holds", [
    ("newton:semi_implicit", "projectile", ["order", "position"], False),    # order 1 as declared
    # the known finding (docs/findings/newton_featherstone_far_from_origin.md): the falling box blows up at
    # every Δt of the ladder, a contradiction in the sweep ("diverged"); ~40 000 Featherstone steps twice
    pytest.param("newton:featherstone", "tumbling_box", ["order", "orientation"], True,
                 marks=pytest.mark.slow),
    ("genesis:euler", "projectile", ["order", "position"], False),           # order 1 as declared
    # the implicit midpoint rotation keeps the torque-free flip (no finding: the sweep's verdicts all hold)
    pytest.param("genesis:implicitfast", "tennis_racket", ["gyroscopic"], False, marks=pytest.mark.slow),
])
def test_newton_and_genesis_reproducers_run_without_rbcheck_and_exit_as_the_sweep_decides(
        variant, scenario, claim, holds, tmp_path):
    engine = variant.split(":")[0]
    allowed, module = _ENGINE_IMPORTS[engine]
    pytest.importorskip(module)
    r = reproducer(variant, load_scenario(scenario), claim)
    assert r.holds is holds, r.output
    assert _imports(r.text) <= {"numpy", "sys", "importlib", "platform", *allowed}
    for name in RBCHECK[:3]:
        assert f"import {name}" not in r.text and f"from {name}" not in r.text
    path = write_reproducer(r, tmp_path / file_name(variant, scenario, " ".join(claim)))
    done = _run_alone(path, tmp_path)
    assert done.returncode == int(holds), done.stdout + done.stderr
    last = done.stdout.strip().splitlines()[-1]
    assert last == r.summary   # the same numbers here and there
    assert last.endswith("DEFECT" if holds else "no defect")
    first = done.stdout.splitlines()[0]
    assert first.startswith(ENGINES[engine][0][0] + " ") and "numpy" in first and "Python" in first


def test_a_jaxsim_scenario_with_gravity_off_the_z_axis_is_refused():
    """jaxsim takes gravity along z only; the adapter turns such a scenario's frame (jaxsim_frame), the
    reproducer's world does not: a rotated projectile is refused with one line, not written wrong."""
    pytest.importorskip("jaxsim")
    with pytest.raises(ReproError, match="gravity is off the z axis"):
        reproducer("jaxsim:rk4", load_scenario("projectile"), ["invariance", "rotation"], run=False)


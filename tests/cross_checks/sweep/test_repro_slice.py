"""cross_checks.sweep.repro_slice: a reproducer's code sliced to what its fixed numbers reach, and only that;
the sliced script prints what the unsliced one prints, to the character, with the same exit code."""
import functools
import os
import subprocess
import sys
import textwrap

import pytest

from cross_checks.scenario import load_scenario
from cross_checks.sweep import repro as R
from cross_checks.sweep.repro_slice import prune
from cross_checks.sweep.repro_text import compact

PLANTED = textwrap.dedent('''\
    import numpy as np
    def build(bodies, variant):
        out = []
        for body in bodies:
            out.append(body[0])
            for part in (body[2] if len(body) > 2 else ()):
                out.append(part)
        if variant == "maximal":
            out.append(1.0)
        else:
            out.append(2.0)
        return out
    def measure(quantity, y):
        if quantity == "orientation":
            return 2.0 * y
        k = {"position": 0}[quantity]
        return y + k
    def main(s):
        y = float(np.sum(build(s["BODIES"], s["VARIANT"])))
        e = measure(s["QUANTITY"], y)
        if e > 1.0:
            print("large")
        print(e)
        return 0
    BODIES, VARIANT, QUANTITY = [(1.0, 2.0)], "maximal", "orientation"
    main(globals())
    ''')


def _printed(code):
    import contextlib
    import io
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "planted", "exec"), {"__name__": "x"})   # noqa: S102 - the planted module
    return out.getvalue()


def test_a_starred_display_is_followed():
    """A list built with a starred element ([(*body[:2], 0.0)]): its length, hence the loop over its tail,
    is the numbers'."""
    planted = PLANTED.replace("        for part in (body[2] if len(body) > 2 else ()):",
                              "        for part in [(*body[:2], 0.0)][1:]:")
    cut = prune(planted)
    assert "for part in" not in cut and _printed(cut) == _printed(planted)


def test_the_numbers_decide_what_goes_and_the_runs_values_never_do():
    cut = prune(PLANTED)
    assert "for part in" not in cut and "out.append(part)" not in cut          # no body has parts
    assert "    out.append(1.0)\n    return out" in cut and "out.append(2.0)" not in cut   # "maximal"
    assert "    return 2.0 * y\n" in cut and "k = " not in cut and "y + k" not in cut   # and what follows
    assert 'if e > 1.0:\n        print("large")' in cut     # decided by what the run computes: kept
    assert _printed(cut) == _printed(PLANTED) == "large\n4.0\n"


CLASS = textwrap.dedent('''\
    class World:
        def __init__(self, variant, parts):
            self.maximal = variant == "maximal"
            self.parts = []
            for part in parts:
                self.parts.append(part)
            self.offsets = [p for p in parts if p > 10.0]
        def step(self, x):
            if self.maximal:
                x = x + 1.0
            for part in self.parts:
                x = x + part
            if self.offsets:
                x = -x
            return x
    def world(variant, parts):
        return World(variant, [float(p) for p in parts])
    def main(s):
        w = world(s["VARIANT"], s["PARTS"])
        print(w.step(1.0))
    VARIANT, PARTS = "multibody", [2.0]
    main(globals())
    ''')


def test_a_methods_branch_on_an_attribute_set_from_the_numbers_goes():
    cut = prune(CLASS)
    assert "if self.maximal:" not in cut and "x + 1.0" not in cut     # "multibody"
    assert "for part in self.parts:" in cut     # a list the script fills (append): its content unknown
    assert "if self.offsets:" in cut            # built by a comprehension over a call's result: unknown
    assert _printed(cut) == _printed(CLASS) == "3.0\n"
    escaped = CLASS.replace("print(w.step(1.0))", "print(list(map(w.step, [1.0])))")   # a bound method
    assert "if self.maximal:" not in prune(escaped)   # the attribute is still the numbers'
    mutated = CLASS.replace("    print(w.step(1.0))", "    w.maximal = s['VARIANT'] == 'multibody'\n"
                            "    print(w.step(1.0))")   # stored again from outside: both values possible
    assert "if self.maximal:" in prune(mutated)


_P = "    print(w.step(1.0))"


@pytest.mark.parametrize("change,kept", [
    # code that may rebind anything: nothing is sliced
    (("main(globals())", "exec('VARIANT = \"maximal\"')\nmain(globals())"), "all"),
    (("main(globals())", "globals()['VARIANT'] = 'maximal'\nmain(globals())"), "all"),
    # a constant bound again at module level (in an if): not the numbers' alone
    (("main(globals())", "if len(PARTS) > 5:\n    VARIANT = 'maximal'\nmain(globals())"), "if self.maximal:"),
    # an attribute set by name, an instance made without naming its class
    ((_P, "    setattr(w, 'maximal', True)\n" + _P), "if self.maximal:"),
    ((_P, "    w = type(w)('maximal', [2.0])\n" + _P), "if self.maximal:"),
    ((_P, "    w = w.__class__('maximal', [2.0])\n" + _P), "if self.maximal:"),
])
def test_a_class_whose_values_the_analysis_cannot_vouch_for_keeps_its_branches(change, kept):
    planted = CLASS.replace(*change)
    assert planted != CLASS
    cut = prune(planted)
    assert cut == planted if kept == "all" else kept in cut
    assert _printed(cut) == _printed(planted)


@pytest.mark.parametrize("change", [
    # the function escapes into code the analysis does not follow: any value may reach it
    ("e = measure(", "e = np.vectorize(measure)("),
    # a followed value mutated by the script: nothing is sliced
    ("    return 0\n", "    s['BODIES'].append((3.0, 4.0, [5.0]))\n    return 0\n"),
    # a value the analysis cannot evaluate (a call into a library, a name it does not know)
    ('if variant == "maximal":', 'if np.str_(variant) == "maximal":'),
    ('if variant == "maximal":', 'if isinstance(None, type):'),
])
def test_what_the_analysis_cannot_vouch_for_stays(change):
    planted = PLANTED.replace(*change)
    cut = prune(planted)
    assert _printed(cut) == _printed(planted)
    if change[0] == "e = measure(":
        assert 'if quantity == "orientation":' in cut and "k = " in cut
    elif "append((3.0" in change[1]:
        assert cut == planted
    else:
        assert "out.append(2.0)" in cut and "for part in" not in cut


def test_a_block_that_would_be_left_empty_and_an_elif_stay():
    planted = (PLANTED.replace("    e = measure(", "    alone()\n    e = measure(")
               .replace("    if e > 1.0:", '    if VARIANT == "x":\n        pass\n    elif e > 1.0:')
               .replace("def main(s):", 'def alone():\n    if QUANTITY == "position":\n        print("p")\n'
                        "def main(s):"))
    cut = prune(planted)
    assert 'if VARIANT == "x":' in cut and "elif e > 1.0" in cut     # the elif chain as it is
    assert 'if QUANTITY == "position":' in cut                        # alone() is not left empty
    assert "for part in" not in cut
    assert _printed(cut) == _printed(planted)


@pytest.mark.parametrize("text", ['"""two\n        lines"""', 'f"""{y}\n        lines"""'])
def test_a_kept_block_holding_a_multi_line_string_keeps_its_indentation(text):
    """Dedenting it would change the string: the if stays as written."""
    ret = "        return 2.0 * y\n"
    planted = PLANTED.replace(ret, f"        print({text})\n{ret}")
    cut = prune(planted)
    assert 'if quantity == "orientation":' in cut and "for part in" not in cut
    assert _printed(cut) == _printed(planted)


#: Runs the script with rbcheck's packages unimportable (as test_repro.py does).
BLOCKED = ("import runpy, sys\n"
           + "".join(f"sys.modules[{m!r}] = None\n" for m in ("rbcheck", "cross_checks", "reference_sim"))
           + "sys.argv = [sys.argv[1]]\nrunpy.run_path(sys.argv[0], run_name='__main__')\n")


def _run_alone(path, tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONSTARTUP")}
    return subprocess.run([sys.executable, "-c", BLOCKED, str(path)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=900)


@pytest.mark.parametrize("variant,scenario,claim", [
    ("mujoco:rk4", "tennis_racket", ["order", "orientation"]),
    ("mujoco:euler", "projectile", ["order", "velocity"]),
    ("mujoco:euler", "long_major_axis_spin", ["drift"]),                     # diverges: exit 1
    ("mujoco:implicit", "tennis_racket", ["gyroscopic"]),
    ("mujoco:euler", "tennis_racket", ["invariance", "rotation"]),
    ("rapier:symplectic_euler_no_gyro", "tennis_racket", ["gyroscopic"]),   # no flip: exit 1
    ("rapier:symplectic_euler", "projectile", ["order", "position"]),
    ("pybullet:multibody", "tennis_racket", ["order", "angular_velocity"]),
    ("pybullet:maximal", "tennis_racket", ["invariance", "scale", "k=0.01", "mu=0.01"]),   # broken: exit 1
    ("drake:implicit_euler", "projectile", ["order", "velocity"]),   # its Newton accuracy set: hoisted
])
def test_a_sliced_script_prints_what_the_unsliced_one_prints(variant, scenario, claim, tmp_path, monkeypatch):
    pytest.importorskip({"rapier": "rapier3d", "drake": "pydrake"}.get(variant.split(":")[0],
                                                                         variant.split(":")[0]))
    sc = load_scenario(scenario)
    sliced = R.reproducer(variant, sc, claim, run=False).text
    monkeypatch.setattr(R, "compact", functools.partial(compact, prune=False))
    whole = R.reproducer(variant, sc, claim, run=False).text
    if claim[0] == "order":   # another quantity's error goes
        assert len(sliced.splitlines()) < len(whole.splitlines())
    if variant == "mujoco:rk4":   # the welded parts' loop
        assert "for j, part in" in whole and "for j, part in" not in sliced
    if variant.startswith("pybullet"):   # the frame of a body off its COM, the variant's branch
        assert "if com_B is not None:" in whole and "if com_B is not None:" not in sliced
        assert "if self.maximal:" in whole and "if self.maximal:" not in sliced
    (tmp_path / "sliced.py").write_text(sliced)
    (tmp_path / "whole.py").write_text(whole)
    a, b = _run_alone(tmp_path / "sliced.py", tmp_path), _run_alone(tmp_path / "whole.py", tmp_path)
    assert a.returncode in (0, 1), a.stderr
    assert (a.returncode, a.stdout) == (b.returncode, b.stdout)

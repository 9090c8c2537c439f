"""``rbcheck repro`` as a command: exit 0 with the script written (whether the claim holds or not, said so),
exit 2 with one line and nothing written for a bad claim, an engine that cannot write one, an engine file."""
import sys

import pytest

from cross_checks.cli import main

pytest.importorskip("mujoco")


def _err_line(capsys) -> str:
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("rbcheck repro:")]
    assert len(err) == 1, err
    return err[0]


def test_a_claim_that_does_not_hold_is_written_and_said(tmp_path, capsys):
    out = tmp_path / "rk4.py"
    assert main(["repro", "mujoco:rk4", "tennis_racket", "--claim", "order", "orientation",
                 "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "no defect here" in said and "measured 4.00, expected 4" in said and "anyway" in said
    text = out.read_text()
    assert "rbcheck repro mujoco:rk4 tennis_racket --claim order orientation" in text
    assert "import cross_checks" not in text and "import rbcheck" not in text


def test_an_invariance_claim_is_written_with_the_transform_as_the_sweep_names_it(tmp_path, capsys):
    out = tmp_path / "inv.py"
    assert main(["repro", "mujoco:euler", "tennis_racket", "--claim", "invariance", "translation", "1e4",
                 "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "invariance translation 1e+04 m" in said and "no defect here" in said and "holds" in said
    assert "rbcheck repro mujoco:euler tennis_racket --claim invariance translation 1e4" in out.read_text()


@pytest.mark.parametrize("args,says", [
    (["mujoco:rk4", "tennis_racket", "--claim", "order", "speed"], "unknown quantity 'speed'"),
    (["mujoco:rk4", "tennis_racket", "--claim", "wobble"], "unknown claim 'wobble'"),
    (["mujoco:rk4", "tennis_racket", "--claim", "invariance", "rotated"],
     "unknown transform 'rotated'; known: translation 10 m;"),
    (["pybullet:maximal", "tennis_racket", "--claim", "invariance", "welded_split"],
     "cannot express welded_split child 0.75 of the mass on tennis_racket"),
    (["mujoco:rk5", "tennis_racket", "--claim", "order", "orientation"], "unknown variant 'rk5'"),
    (["mujoco:rk4", "spring_pendulum", "--claim", "drift"], "forces change with the state"),
])
def test_bad_input_is_one_line_exit_2_and_nothing_written(tmp_path, capsys, args, says):
    out = tmp_path / "x.py"
    assert main(["repro", *args, "--out", str(out)]) == 2
    assert says in _err_line(capsys)
    assert not out.exists()


def test_an_engine_that_cannot_write_one_yet_is_one_line_exit_2_naming_those_that_can(tmp_path, capsys,
                                                                                     monkeypatch):
    from cross_checks.sweep import repro
    monkeypatch.delitem(repro.ENGINES, "drake")   # every built-in engine can: one taken out of the table
    out = tmp_path / "x.py"
    assert main(["repro", "drake:semi_explicit_euler", "tennis_racket", "--claim", "gyroscopic",
                 "--out", str(out)]) == 2
    assert f"drake cannot write reproducers yet; these can: {', '.join(repro.ENGINES)}" in _err_line(capsys)
    assert not out.exists()


def test_the_output_must_be_a_python_file(tmp_path, capsys):
    assert main(["repro", "mujoco:rk4", "tennis_racket", "--claim", "drift", "--out",
                 str(tmp_path / "x.txt")]) == 2
    assert "must end in .py" in _err_line(capsys)


def test_an_engine_file_cannot_write_a_reproducer_its_command_is_one(tmp_path, capsys):
    prog = tmp_path / "engine.py"
    prog.write_text("import sys\n")
    toml = tmp_path / "mine.toml"
    toml.write_text(f'name = "repro_file"\nversion = "1"\n[variants.euler]\norder = 1\ndescription = "x"\n'
                    f'command = ["{sys.executable}", "engine.py", "{{scenario_json}}", "{{out_csv}}"]\n')
    out = tmp_path / "x.py"
    from cross_checks import engines
    try:   # a name no other test registers (another test's engine file "mine" may still be registered)
        assert main(["repro", "repro_file:euler", "tennis_racket", "--claim", "order", "orientation",
                     "--out", str(out), "--engine-file", str(toml)]) == 2
    finally:
        engines.reset_registry()
    line = _err_line(capsys)
    assert "engine file" in line and "its command is the reproducer" in line
    assert not out.exists()

"""The first five minutes: `rbcheck --version`, `run --engine ENGINE` (its default variant), `list --json`."""
import json
import tomllib
from pathlib import Path

import pytest

import cross_checks
from cross_checks.cli import main

CATALOG = Path(cross_checks.__file__).parent / "scenario" / "catalog"


def test_version_names_rbcheck_and_the_engines_it_runs(capsys):
    from importlib.metadata import PackageNotFoundError, version

    import mujoco
    import numpy
    import pybullet  # noqa: F401

    import reference_sim
    assert main(["--version"]) == 0
    first, second, third = capsys.readouterr().out.splitlines()
    assert first == f"rbcheck {reference_sim.__version__}"
    assert f"numpy {numpy.__version__}" in second
    assert f"mujoco {mujoco.__version__}" in third
    assert "pybullet 3.2.7" in third  # pybullet has no __version__; the pinned release (pyproject.toml)
    try:   # every engine that imports is listed with its version (Drake when its extra is installed)
        import pydrake  # noqa: F401
        assert f"drake {version('drake')}" in third
    except (ImportError, PackageNotFoundError):
        assert "drake: drake is not installed" in third


def test_an_engine_name_alone_runs_the_engines_own_default(tmp_path, capsys):
    """`--engine mujoco` is mujoco:euler, MuJoCo's own default integrator (asked of MuJoCo, not of rbcheck),
    bit for bit; `--engine reference` is the course's step."""
    import mujoco
    assert mujoco.MjModel.from_xml_string("<mujoco/>").opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
    for bare, full in (("mujoco", "mujoco:euler"), ("reference", "reference:course")):
        a, b = tmp_path / f"{bare}.csv", tmp_path / f"{bare}_full.csv"
        assert main(["run", "projectile", "--engine", bare, "--out", str(a), "--duration", "0.2"]) == 0
        assert f"with {full} " in capsys.readouterr().out
        assert main(["run", "projectile", "--engine", full, "--out", str(b), "--duration", "0.2"]) == 0
        assert a.read_bytes() == b.read_bytes()
        assert json.loads(a.with_suffix(".json").read_text())["variant"] == full


def test_run_help_says_an_engine_name_alone_is_its_default(capsys):
    assert main(["run", "--help"]) == 0
    assert "engine name alone runs its default variant" in " ".join(capsys.readouterr().out.split())


def test_list_json_is_the_catalog_and_every_variant(capsys):
    from cross_checks.engines import all_variants
    assert main(["list", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    files = {p.stem: tomllib.loads(p.read_text()) for p in CATALOG.glob("*.toml")}
    assert [s["name"] for s in listed["scenarios"]] == sorted(files)
    for s in listed["scenarios"]:
        toml = files[s["name"]]
        assert (s["duration_s"], s["dt_s"]) == (toml["duration"], toml["dt"])
        assert s["dt_ladder_s"] == toml.get("dt_ladder", [toml["dt"]])
        assert s["description"] == toml.get("description", "")
    assert [v["name"] for v in listed["variants"]] == [v.name for v in all_variants()]
    defaults = [(v["engine"], v["name"]) for v in listed["variants"] if v["default"]]
    engines = {v["engine"] for v in listed["variants"] if not v["name"].endswith(":*")}
    assert sorted(e for e, _ in defaults) == sorted(engines)  # exactly one default per loadable engine
    assert {"reference": "reference:course", "mujoco": "mujoco:euler",
            "pybullet": "pybullet:multibody"}.items() <= dict(defaults).items()
    orders = {v.name: v.order for v in all_variants()}
    assert all(v["declared_order"] == orders[v["name"]] and v["description"] for v in listed["variants"])
    assert ([v["declared_order"] for v in listed["variants"] if v["engine"] == "reference"]
            == [1, 1, 1, 1, 1, 2, 2, 4, 1, 1, 1, 1, 2, 2, 2, 2])   # the textbook schemes, then the gyroscopic


def test_list_json_of_a_user_engine_file_marks_its_first_variant_default(tmp_path, capsys):
    (tmp_path / "e.toml").write_text('name = "mine"\n'
                                     'version = "1"\n'
                                     '[variants.a]\n'
                                     'order = 1\n'
                                     'description = "A"\n'
                                     'command = ["true", "{scenario_json}", "{out_csv}"]\n'
                                     '[variants.b]\n'
                                     'order = 2\n'
                                     'description = "B"\n'
                                     'command = ["true", "{scenario_json}", "{out_csv}"]\n')
    assert main(["list", "--json", "--engine-file", str(tmp_path / "e.toml")]) == 0
    mine = [v for v in json.loads(capsys.readouterr().out)["variants"] if v["engine"] == "mine"]
    assert [(v["name"], v["default"]) for v in mine] == [("mine:a", True), ("mine:b", False)]


@pytest.mark.parametrize("engine, words", [
    ("course", "did you mean reference:course?"),
    ("nope", "unknown engine 'nope'"),
])
def test_a_bare_name_that_is_no_engine_is_exit_2_with_a_hint(tmp_path, capsys, engine, words):
    assert main(["run", "projectile", "--engine", engine, "--out", str(tmp_path / "a.csv")]) == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "a.csv").exists()

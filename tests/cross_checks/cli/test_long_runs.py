"""`rbcheck sweep` with long runs, end to end through the CLI (docs/scenario.md "Long runs"): a tiny long run
file, every variant's row in long_runs.csv, the integrators page, exit 1 when a variant does not keep what it
declares (the planted drift toward the intermediate axis), `--long` and `rbcheck list`."""
import csv
import json

import pytest

from cross_checks.cli import main
from cross_checks.cli.parser import build_parser
from tests.helpers.scenarios import TINY_LONG_RUN
from tests.mutants import long_run_mutants


@pytest.fixture
def long_file(tmp_path, monkeypatch):
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
    p = tmp_path / "tiny_long.toml"
    p.write_text(TINY_LONG_RUN, encoding="utf-8")
    return p


def test_a_tiny_long_run_end_to_end(long_file, tmp_path, capsys):
    out = tmp_path / "res"
    rc = main(["sweep", str(long_file), "--engines", "reference:jolt_gyro", "reference:lp_midpoint",
               "mujoco:rk4", "--out", str(out), "--jobs", "1"])
    text = capsys.readouterr().out
    assert rc == 0 and text.strip().splitlines()[-1].endswith("verdicts as expected"), text[-500:]
    with open(out / "long_runs.csv", encoding="utf-8", newline="") as fh:
        rows = {r["engine"]: r for r in csv.DictReader(fh)}
    assert set(rows) == {"reference:jolt_gyro", "reference:lp_midpoint", "mujoco:rk4"}
    assert rows["reference:jolt_gyro"]["verdict"] == "toward_intermediate"
    assert rows["reference:jolt_gyro"]["matches_expectation"] == "true"
    assert rows["reference:lp_midpoint"]["finding"] == "" and rows["mujoco:rk4"]["matches_expectation"] == ""
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert [s["name"] for s in summary["long_run_scenarios"]] == ["tiny_long"]
    assert summary["run"]["long_runs"]["runs"] == 3
    assert "tiny_long" not in (out / "results.csv").read_text()      # no ladder rows
    page = (out / "integrators.html").read_text(encoding="utf-8")
    assert "reference:jolt_gyro on tiny_long: drifts toward the intermediate axis" in page
    # the report re-renders from the saved files alone
    assert main(["report", str(out)]) == 0


def test_a_declared_keeper_that_drifts_fails_the_sweep(long_file, tmp_path, capsys, monkeypatch):
    long_run_mutants()["planted_keeps"](monkeypatch)
    rc = main(["sweep", str(long_file), "--engines", "planted_keeps:step", "--out", str(tmp_path / "res"),
               "--jobs", "1"])
    _, err = capsys.readouterr()
    assert rc == 1
    line = next(ln for ln in err.splitlines() if "planted_keeps:step on tiny_long (long run):" in ln)
    assert "the energy drifted by" in line and "although it declares that it keeps it" in line
    assert "its separatrix distance moved (drifts toward the intermediate axis (energy → L²/2I₂)" in line


def test_long_adds_the_catalogs_long_runs_and_list_shows_them(capsys):
    assert build_parser().parse_args(["sweep", "--long", "--out", "x"]).long
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "Long runs (in the default sweep; with SCENARIOs named: rbcheck sweep --long" in out
    for n in ("long_major_axis_spin", "long_minor_axis_spin", "long_tennis_racket"):
        assert n in out
    assert main(["list", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in listed["long_runs"]] == ["long_major_axis_spin", "long_minor_axis_spin",
                                                        "long_tennis_racket"]


@pytest.mark.parametrize("argv, has_long", [([], True), (["--no-long"], False), (["projectile"], False),
                                            (["projectile", "--long"], True)])
def test_the_default_sweep_has_the_long_runs_and_no_long_leaves_them_out(monkeypatch, tmp_path, argv,
                                                                          has_long):
    import cross_checks.cli.sweep as sweep
    from cross_checks.cli.errors import BadInput
    from cross_checks.scenario import catalog_names, long_run_names
    seen = {}

    def capture(args, scenarios, variants, skipped):   # the scenarios the sweep would run; nothing runs
        seen["names"] = [s.name for s in scenarios]
        raise BadInput("stopped by the test")

    monkeypatch.setattr(sweep, "_run_sweep", capture)
    assert main(["sweep", *argv, "--engines", "reference:course", "--out", str(tmp_path / "out")]) == 2
    assert (set(long_run_names()) <= set(seen["names"])) is has_long
    assert not has_long or set(long_run_names()).isdisjoint(catalog_names())

"""``rbcheck fuzz`` as a command: exit codes, one-line errors, the summary, the
page and the marker it writes."""
import json

import pytest

from cross_checks.cli import main
from cross_checks.fuzz import campaign


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache"


def test_a_clean_campaign_exits_0_with_its_summary_and_page(tmp_path, cache, capsys, monkeypatch):
    monkeypatch.setattr(campaign, "BATCH", 4)
    out = tmp_path / "fz"
    assert main(["fuzz", "--engines", "reference:midpoint",
                 "--budget", "0.5", "--jobs", "1", "--out", str(out)]) == 0
    s = json.loads((out / "fuzz.json").read_text())
    # batches until the budget: one on a loaded machine, more on an idle one (0.5 s)
    assert s["format"] == campaign.FORMAT and s["cases"]["judged"] >= 1
    assert s["per_variant"]["reference:midpoint"]["properties"]["one_step_order"][0] > 0
    html = (out / "index.html").read_text()
    assert "rbcheck fuzz" in html and "reference:midpoint" in html and "no property violated" in html
    assert (out / ".rbcheck-results.json").is_file()
    assert "cases/s" in capsys.readouterr().out


@pytest.mark.parametrize("argv, where", [
    (["--engines", "nosuch:engine"], "--engines"),
    (["--budget", "-3"], "--budget"),
    (["--seed", "x"], "--seed"),
])
def test_bad_input_is_one_line_and_exit_2(argv, where, tmp_path, capsys):
    assert main(["fuzz", *argv, "--out", str(tmp_path / "fz")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert where in err[-1] and "Traceback" not in "".join(err)
    assert not (tmp_path / "fz").exists()


def test_an_output_that_is_not_rbchecks_is_refused_before_any_work(tmp_path, capsys):
    d = tmp_path / "mine"
    d.mkdir()
    (d / "notes.txt").write_text("keep")
    assert main(["fuzz", "--engines", "reference:rk4", "--out", str(d)]) == 2
    assert "--out" in capsys.readouterr().err and (d / "notes.txt").read_text() == "keep"


def test_the_confirmation_uses_exactly_the_sweeps_exit_rule():
    """shrink.sweep_gate_failures repeats cli.sweep._gate_failures (the fuzz may not import the cli layer)."""
    from cross_checks.cli.sweep import _gate_failures
    from cross_checks.fuzz.shrink import sweep_gate_failures
    summaries = [
        {"convergence": [{"engine": "e:v", "scenario": "s", "quantity": "position", "assessment": "order 2",
                          "matches_expectation": False},
                         {"engine": "e:w", "scenario": "s", "quantity": "velocity", "assessment": "ok",
                          "matches_expectation": True}],
         "agreement": [{"a": "x", "b": "y", "scenario": "s", "agrees": False}], "run": {"failed_runs": 2}},
        {"convergence": [], "agreement": [{"a": "x", "b": "y", "scenario": "s", "agrees": True}], "run": {}},
    ]
    for s in summaries:
        assert sweep_gate_failures(s) == _gate_failures(s)


def test_a_campaign_into_a_directory_that_cannot_be_renamed_is_written(tmp_path, cache, monkeypatch):
    """``--out`` a mount point (a Docker volume): the campaign ran, then the final rename failed with EBUSY
    and everything was discarded (issue 45). Simulated: renaming DIR itself raises EBUSY."""
    import errno
    import os

    import cross_checks.sweep.results_dir as rd
    monkeypatch.setattr(campaign, "BATCH", 4)
    out = tmp_path / "fz"
    args = ["fuzz", "--engines", "reference:midpoint", "--budget", "0.5", "--jobs", "1", "--out", str(out)]
    assert main(args) == 0
    real = os.replace

    def replace(src, dst, *a, **k):
        if os.path.abspath(src) == str(out):
            raise OSError(errno.EBUSY, os.strerror(errno.EBUSY), str(src))
        return real(src, dst, *a, **k)
    monkeypatch.setattr(rd.os, "replace", replace)
    (out / "index.html").write_text("previous")
    assert main(args) == 0
    assert (out / "index.html").read_text() != "previous" and (out / "fuzz.json").is_file()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert not [p for p in out.iterdir() if p.name.startswith(".") and p.name != ".rbcheck-results.json"]

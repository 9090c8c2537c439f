"""The results directory: recognised by rbcheck's marker only; nothing the user put anywhere is ever
deleted; replacing keeps the previous results until the new ones are complete; what a killed run
leaves beside it is removed (or put back) by the next run, and only when provably rbcheck's and stale."""
import hashlib
import json
import os
import socket

import pytest

from cross_checks.cli import main
from cross_checks.sweep.jobs import SCHEMA_VERSION
from cross_checks.sweep.results_dir import (
    MARKER,
    ResultsDirError,
    check_output_dir,
    inside,
    owned_name,
    read_marker,
    remove_stale_siblings,
    replace_dir,
    safe_file_stem,
)
from tests.helpers.scenarios import TINY
from tests.helpers.sweeps import file_tree as tree


@pytest.fixture
def tiny(tmp_path, isolated_cache):
    f = tmp_path / "tiny.toml"
    f.write_text(TINY)
    return str(f)


@pytest.fixture
def made(tiny_results):
    return tiny_results


def copy_of(made, tmp_path):
    import shutil
    shutil.copytree(made, tmp_path / "res")
    return tmp_path / "res"


def sweep(tiny, out, *extra):
    return main(["sweep", tiny, "--engines", "reference:course", "--jobs", "1", "--out", str(out), *extra])


def test_a_sweep_writes_the_marker_listing_every_file_it_wrote(tiny, tmp_path, made):
    out = copy_of(made, tmp_path)
    m = read_marker(out)
    assert m["schema_version"] == SCHEMA_VERSION and m["format"] == "rbcheck results directory"
    on_disk = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()} - {MARKER}
    assert set(m["files"]) == on_disk and "results.csv" in on_disk and "index.html" in on_disk
    check_output_dir(str(out))  # its own directory may be replaced (test_lifecycle.py replaces one for real)


def test_out_dot_in_a_folder_with_a_paper_is_refused_and_the_paper_stays(tiny, tmp_path, monkeypatch, capsys):
    folder = tmp_path / "paper"
    folder.mkdir()
    (folder / "paper.tex").write_text("my thesis")
    (folder / "summary.json").write_text("{}")  # a file of that name used to make any folder 'rbcheck's'
    monkeypatch.chdir(folder)
    before = tree(folder)
    assert sweep(tiny, ".") == 2
    assert sweep(tiny, "") == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and "current directory" in err[0] and "empty path" in err[1]
    assert tree(folder) == before


def test_a_non_empty_folder_without_the_marker_is_refused_whatever_it_holds(tiny, tmp_path, capsys):
    out = tmp_path / "notes"
    out.mkdir()
    (out / "summary.json").write_text("{}")
    (out / "results.csv").write_text("scenario\n")
    (out / "paper.pdf").write_bytes(b"%PDF")
    before = tree(out)
    assert sweep(tiny, out) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not an rbcheck results directory" in err and MARKER in err
    assert tree(out) == before and not [p for p in tmp_path.iterdir() if ".rbcheck-" in p.name]


def test_a_results_directory_holding_a_users_file_is_refused_and_the_file_stays(tiny, tmp_path, capsys, made):
    out = copy_of(made, tmp_path)
    (out / "plots" / "my_figure.svg").write_text("<svg/>")
    before = tree(out)
    assert sweep(tiny, out) == 2
    assert "holds files rbcheck did not write (plots/my_figure.svg)" in capsys.readouterr().err
    assert tree(out) == before


def test_a_marker_of_a_newer_schema_is_not_replaced(tiny, tmp_path, capsys, made):
    out = copy_of(made, tmp_path)
    m = read_marker(out)
    (out / MARKER).write_text(json.dumps({**m, "schema_version": SCHEMA_VERSION + 1}))
    assert sweep(tiny, out) == 2 and "newer rbcheck" in capsys.readouterr().err


@pytest.mark.parametrize("make, words", [
    (lambda t: (t / "file.txt").write_text("x") and t / "file.txt" / "res", "is not a directory"),
    (lambda t: t / "missing" / "res", "does not exist"),
    (lambda t: t / "file.txt", "exists and is not a directory"),
])
def test_unusable_out_paths_exit_2_in_one_line_before_any_work(tiny, tmp_path, capsys, make, words):
    (tmp_path / "file.txt").write_text("x")
    out = make(tmp_path)
    assert sweep(tiny, out) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err and "Traceback" not in err
    assert not (tmp_path / "cache").exists()  # nothing ran


def test_a_folder_nobody_can_write_in_is_refused_before_any_work(tiny, tmp_path, capsys):
    # Root ignores file modes, so the check creates a file for real; /proc refuses one even to root.
    with pytest.raises(ResultsDirError, match="cannot write in /proc"):
        check_output_dir("/proc/rbcheck-results")
    assert sweep(tiny, "/proc/rbcheck-results") == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_replacing_moves_a_file_dropped_in_during_the_run_instead_of_deleting_it(tmp_path):
    out, staging = tmp_path / "res", tmp_path / "new"
    out.mkdir()
    (out / "results.csv").write_text("old")
    (out / MARKER).write_text(json.dumps({"format": "rbcheck results directory", "schema_version": 1,
                                          "files": ["results.csv"]}))
    (out / "late_note.txt").write_text("written while the sweep ran")
    staging.mkdir()
    (staging / "results.csv").write_text("new")
    replace_dir(staging, out)
    assert (out / "results.csv").read_text() == "new"
    assert (out / "late_note.txt").read_text() == "written while the sweep ran"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]


def _dead_pid():
    pid = os.fork()
    if pid == 0:
        os._exit(0)
    os.waitpid(pid, 0)
    return pid


def _named(tmp_path, kind, pid, host=None, start=12345):
    host = host or hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]
    p = tmp_path / f".res.rbcheck-{kind}-{host}-{pid}-{start}-0badf00d"
    p.mkdir()
    (p / "results.csv").write_text(kind)
    return p


def test_the_next_run_removes_stale_staging_only_when_provably_rbchecks_and_its_owner_dead(tmp_path):
    out = tmp_path / "res"
    out.mkdir()
    dead = _named(tmp_path, "staging", _dead_pid())
    start_of_1 = int(open("/proc/1/stat").read().rsplit(")", 1)[1].split()[19])
    alive = _named(tmp_path, "staging", 1, start=start_of_1)  # pid 1 lives: its staging is not stale
    reused = _named(tmp_path, "staging", 1, start=start_of_1 + 1)  # pid 1 now is another process
    other_host = _named(tmp_path, "staging", _dead_pid(), host="00000000")
    lookalike = tmp_path / ".res.tmp-12345"
    lookalike.mkdir()
    mine = tmp_path / owned_name(".res.", "staging")
    mine.mkdir()
    done = remove_stale_siblings(out)
    assert not dead.exists() and not reused.exists() and len(done) == 2
    assert alive.exists() and other_host.exists() and lookalike.exists() and mine.exists()


def test_previous_results_left_between_the_two_renames_are_put_back(tmp_path):
    out = tmp_path / "res"
    old = _named(tmp_path, "old", _dead_pid())
    remove_stale_siblings(out)
    assert (out / "results.csv").read_text() == "old" and not old.exists()


@pytest.mark.parametrize("name", ["../../x", "/tmp/x", "a\x00b", "x" * 300, "..", ".", "",
                                  "scenario/../../..", "CON", "tennis_racket"])
def test_file_names_from_data_stay_inside_the_directory(tmp_path, name):
    stem = safe_file_stem(name)
    assert stem and len(stem) <= 100 and "/" not in stem and "\x00" not in stem and stem not in (".", "..")
    p = inside(tmp_path, f"scenario-{stem}.html")
    assert p.parent == tmp_path.resolve()
    if name == "tennis_racket":
        assert stem == name  # valid names are kept as they are


def test_inside_refuses_an_escape(tmp_path):
    for bad in ("../x", "/tmp/x", "a/../../x"):
        with pytest.raises(ResultsDirError, match="leaves"):
            inside(tmp_path, bad)


# --- an --out that cannot be renamed: a mount point (issue 45) ----------------------------------------------

def _rename_of_out_fails(monkeypatch, out, errno_=16):
    """os.replace raises EBUSY ("Device or resource busy", what Linux says for a mount point) when asked to
    move ``out`` itself, as it does for a Docker volume or a tmpfs mounted there."""
    import cross_checks.sweep.results_dir as rd
    real = os.replace

    def replace(src, dst, *a, **k):
        if os.path.abspath(src) == str(out):
            raise OSError(errno_, os.strerror(errno_), str(src))
        return real(src, dst, *a, **k)
    monkeypatch.setattr(rd.os, "replace", replace)


def test_a_sweep_into_a_directory_that_cannot_be_renamed_fills_it_in_place(tiny, tmp_path, made, monkeypatch):
    """Before: everything computed, then "Device or resource busy" on the final rename, and all discarded."""
    out = copy_of(made, tmp_path)
    (out / "index.html").write_text("previous")
    _rename_of_out_fails(monkeypatch, out)
    assert sweep(tiny, out) in (0, 1)
    marker = read_marker(out)
    assert set(marker["files"]) == set(tree(out)) - {MARKER} and "results.csv" in marker["files"]
    assert (out / "index.html").read_text() != "previous"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]   # nothing left beside it
    assert not [p for p in out.iterdir() if p.name.startswith(".") and p.name != MARKER]


def test_a_mount_point_gets_its_staging_folder_inside_and_is_filled_in_place(tiny, tmp_path, made,
                                                                             monkeypatch):
    import cross_checks.sweep.results_dir as rd
    out = copy_of(made, tmp_path)
    monkeypatch.setattr(rd.os.path, "ismount", lambda p: os.path.abspath(p) == str(out))
    _rename_of_out_fails(monkeypatch, out)
    seen = []
    real_staging = rd.staging_dir
    monkeypatch.setattr("cross_checks.sweep.run.staging_dir",
                        lambda o: seen.append(real_staging(o)) or seen[-1])
    assert sweep(tiny, out) in (0, 1)
    assert seen and seen[0].parent == out   # on the mount's own file system, not beside it
    assert "results.csv" in read_marker(out)["files"]
    assert not [p for p in out.iterdir() if p.name.startswith(".") and p.name != MARKER]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_a_baseline_into_a_directory_that_cannot_be_renamed_is_written(tmp_path, made, monkeypatch):
    from cross_checks.gates.baseline import write_baseline
    out = tmp_path / "base"
    write_baseline(made, out)
    (out / "results.csv").write_text("previous")
    _rename_of_out_fails(monkeypatch, out.resolve())
    write_baseline(made, out)
    assert sorted(p.name for p in out.iterdir()) == ["results.csv", "summary.json"]
    assert (out / "results.csv").read_text() != "previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["base"]


def test_an_in_place_replacement_killed_half_way_is_put_right_by_the_next_run(tmp_path, monkeypatch):
    import cross_checks.sweep.results_dir as rd
    out = tmp_path / "res"
    out.mkdir()
    monkeypatch.setattr(rd.os.path, "ismount", lambda p: os.path.abspath(p) == str(out))
    # killed after moving the previous results aside and one new file in, before the new marker
    host = hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]
    old = out / f".rbcheck-old-{host}-{_dead_pid()}-1-0badf00d"
    old.mkdir()
    (old / "results.csv").write_text("old")
    (old / MARKER).write_text("old marker")
    (out / "results.csv").write_text("new")
    (out / "summary.json").write_text("new")
    remove_stale_siblings(out)
    assert {p.name: p.read_text() for p in out.iterdir()} == {"results.csv": "old", MARKER: "old marker"}
    # killed after the new marker came in, before the previous results were disposed of: the new ones stand
    old.mkdir()
    marker = json.dumps({"format": "rbcheck results directory", "schema_version": 1, "written_by": "rbcheck",
                         "files": ["results.csv"]})
    (old / "results.csv").write_text("older")
    (old / MARKER).write_text(marker)
    (out / "results.csv").write_text("newest")
    (out / MARKER).write_text(marker)
    remove_stale_siblings(out)
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "results.csv"]
    assert (out / "results.csv").read_text() == "newest"



def test_a_baseline_killed_inside_a_mount_point_does_not_block_the_next(tmp_path, made, monkeypatch):
    import cross_checks.sweep.results_dir as rd
    from cross_checks.gates.baseline import write_baseline
    out = tmp_path / "base"
    out.mkdir()
    monkeypatch.setattr(rd.os.path, "ismount", lambda p: os.path.abspath(p) == str(out))
    host = hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]
    (out / f".rbcheck-staging-{host}-{_dead_pid()}-1-0badf00d").mkdir()   # a killed baseline's
    write_baseline(made, out)
    assert sorted(p.name for p in out.iterdir()) == ["results.csv", "summary.json"]

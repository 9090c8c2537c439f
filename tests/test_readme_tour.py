"""The README's "A short tour" runs exactly as written, line after line, in a fresh copy of the repository
where only the install step has happened (the venv running these tests stands in for `.venv`): a new
user who pastes it sees every command succeed, bare `rbcheck` included."""
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def tour_lines() -> list:
    """The commands of the first bash block after the "## A short tour" heading, comments kept."""
    section = README.split("## A short tour", 1)[1]
    block = re.search(r"```bash\n(.*?)```", section, re.S)
    assert block, "README: no bash block under '## A short tour'"
    return [ln for ln in block[1].splitlines() if ln.strip() and not ln.lstrip().startswith("#")]


def _fresh_copy(dest: Path) -> None:
    """The repository's files as a clone has them: tracked and not ignored, no results, caches or venv."""
    try:
        listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                                cwd=ROOT, capture_output=True, check=True).stdout.decode().split("\0")
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: cannot tell a clone's files from local ones")
    for rel in filter(None, listed):
        src = ROOT / rel
        if src.is_file():
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / rel)


def _script(lines) -> str:
    """Each tour line in one shell (so `. .venv/bin/activate` carries), stopping at the first failure
    with the line that failed."""
    out = ["set -u"]
    for ln in lines:
        quoted = ln.replace("'", "'\\''")
        out.append(f"echo '+ {quoted}'")
        out.append(f"{ln}\nrc=$?; if [ $rc -ne 0 ]; then echo 'TOUR LINE "
                   f"FAILED (exit '$rc'): {quoted}' >&2; exit 1; fi")
    return "\n".join(out) + "\n"


def _path_without_rbcheck() -> str:
    """PATH without any directory holding an `rbcheck`: the tour itself must put it there."""
    keep = [d for d in os.environ.get("PATH", os.defpath).split(os.pathsep)
            if d and not (Path(d) / "rbcheck").exists()]
    return os.pathsep.join(keep)


@pytest.mark.integration
def test_the_readme_tour_runs_as_written_in_a_fresh_clone(tmp_path):
    venv = Path(sys.prefix)
    if venv == Path(sys.base_prefix) or not (venv / "bin" / "activate").is_file():
        pytest.skip(
            "the tests do not run in a virtual environment: no .venv to stand in for the install step")
    clone = tmp_path / "rbcheck"
    _fresh_copy(clone)
    (clone / ".venv").symlink_to(venv, target_is_directory=True)
    before = {p for p in clone.rglob("*") if p.is_file()}
    env = {**os.environ, "PATH": _path_without_rbcheck(), "RBCHECK_CACHE_DIR": str(tmp_path / "cache"),
           "MPLBACKEND": "Agg"}
    env.pop("VIRTUAL_ENV", None)
    p = subprocess.run(["bash", "-c", _script(tour_lines())], cwd=clone, env=env, capture_output=True,
                       text=True, timeout=600)
    assert p.returncode == 0, f"{p.stderr[-3000:]}\n--- stdout ---\n{p.stdout[-3000:]}"
    out = p.stdout
    assert re.search(r"^rbcheck \d+\.\d+\.\d+$", out, re.M), "rbcheck --version"
    assert "tennis_racket with mujoco:euler" in out, "run --engine mujoco runs MuJoCo's default variant"
    assert "initial state" in out and "angular velocity" in out, "show prints the initial conditions"
    assert "OK: no regression" in out and "not compared:" in out, "compare of the subset"
    for f in ("t.csv", "t.json", "m.csv", "b.csv", "results/index.html", "results/summary.json", "diff.md",
              "my-baseline/summary.json"):
        assert (clone / "tour" / f).is_file(), f"the tour should have written tour/{f}"
    # everything the tour wrote is in its git-ignored scratch folder: the clone stays clean
    stray = sorted(str(p.relative_to(clone)) for p in clone.rglob("*") if p.is_file() and p not in before
                   and p.relative_to(clone).parts[0] not in ("tour", ".venv") and "__pycache__" not in p.parts
                   and p.name != "MUJOCO_LOG.TXT")
    assert not stray, f"the tour left files outside tour/: {stray}"
    assert "tour/" in (ROOT / ".gitignore").read_text().splitlines()


def test_the_tour_has_no_line_that_needs_what_a_fresh_clone_lacks():
    """Every file a tour line reads is in the repository or written by an earlier line."""
    written = set()
    for ln in tour_lines():
        args = ln.split("#", 1)[0].split()
        for a in args[2:]:
            if (re.search(r"\.(toml|csv)$", a) and not a.startswith("-")
                    and args[args.index(a) - 1] != "--out"):
                assert (ROOT / a).is_file() or a in written, (
                    f"tour line reads {a}, which nothing provides: {ln}")
        if "--out" in args:
            written.add(args[args.index("--out") + 1])
            assert args[args.index("--out") + 1].startswith("tour/"), f"the tour writes into tour/: {ln}"


def test_every_output_the_readme_writes_is_git_ignored():
    """Issue 44, point 10: the C example wrote `results/` at the repository's root, which git did not ignore.
    Every `--out` / `--markdown` / `--json` / `--plot` path and `rbcheck baseline`'s OUT_DIR in the README's
    and the examples' commands is ignored by git (a user's `git status` stays clean)."""
    import re
    import subprocess
    texts = [(ROOT / "README.md").read_text(), (ROOT / "examples" / "c_engine" / "README.md").read_text()]
    paths = set()
    for text in texts:
        for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
            block = block.replace("\\\n", " ")
            paths |= set(re.findall(r"--(?:out|markdown|json|plot) ([^-\s]\S*)", block))
            paths |= {m.split()[-1] for m in re.findall(r"rbcheck baseline \S+ \S+", block)}
    assert "tour/cbody/" in paths and len(paths) > 5, paths
    for p in sorted(paths):
        ignored = subprocess.run(["git", "check-ignore", "-q", "--no-index", p.rstrip("/") + "/x"], cwd=ROOT)
        assert ignored.returncode == 0, f"{p} is not ignored by git"

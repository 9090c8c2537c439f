"""Every file path and every dotted name the repository cites exists: the docs, the README, the report
template, docstrings and comments name `cross_checks/...`, `docs/...`, `tests/...` and
`cross_checks.pkg.module.name` — after a module moves, a stale citation sends a reader nowhere."""
import importlib
import os
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TOP = ("cross_checks", "reference_sim", "reports", "tests", "docs", "benchmarks", "examples", "baselines")
SUFFIXES = (".py", ".md", ".html", ".toml", ".yml")
PATH_RE = re.compile(r"(?<![\w/.-])((?:%s)/[\w./-]*\w)" % "|".join(TOP))
DOTTED_RE = re.compile(r"(?<![\w.])((?:cross_checks|reference_sim|reports)(?:\.[A-Za-z_]\w*)+)")
SKIP_DIRS = {".git", ".venv", "build", "__pycache__", "node_modules"}


def _files():
    """The repository's text files (not this one: it plants stale citations on purpose)."""
    out = []
    for folder, dirs, names in os.walk(ROOT):
        dirs[:] = [d for d in dirs
                   if d not in SKIP_DIRS and not d.endswith(".egg-info") and not d.startswith(".")]
        out += [Path(folder) / n for n in names if n.endswith(SUFFIXES)]
    return [p for p in out if p != Path(__file__).resolve()]


def _resolves(name: str) -> bool:
    """``a.b.c``: the longest importable module prefix, then attributes for the rest."""
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def stale_citations(files) -> list:
    """(file, cited text) for every cited path that does not exist and dotted name that does not resolve."""
    bad = []
    for f in map(Path, files):
        text = f.read_text(encoding="utf-8", errors="ignore")
        for m in PATH_RE.finditer(text):
            path = m.group(1).rstrip(".")
            if not any(c in path for c in "*{<") and not (ROOT / path).exists():
                bad.append((f.name, path))
        for m in DOTTED_RE.finditer(text):
            name = m.group(1)
            if not name.endswith(SUFFIXES + (".json", ".csv")) and not _resolves(name):
                bad.append((f.name, name))
    return sorted(set(bad))


def test_every_cited_path_and_module_exists():
    assert stale_citations(_files()) == []


def test_a_stale_citation_is_found(tmp_path):
    planted = tmp_path / "planted.md"
    planted.write_text("see `cross_checks/tolerances.py` and cross_checks.metrics.fit_convergence, not "
                       "cross_checks.analysis.convergence.fit_nothing; cross_checks/core/tolerances.py "
                       "and cross_checks.analysis.convergence.fit_convergence exist")
    assert [cited for _, cited in stale_citations([planted])] == [
        "cross_checks.analysis.convergence.fit_nothing", "cross_checks.metrics.fit_convergence",
        "cross_checks/tolerances.py"]

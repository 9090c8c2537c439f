"""Results directories for tests: built by real sweeps once per test run and shared, with a private
cache, and read back the way tests compare them."""
import csv
import fcntl
import os
import shutil
from contextlib import contextmanager
from pathlib import Path

import pytest

#: results.csv columns that legitimately differ between two runs of the same sweep (timing, cache use).
RUN_DEPENDENT_COLUMNS = ("wall_s", "engine_s", "cached")


@contextmanager
def private_cache(path: Path):
    """RBCHECK_CACHE_DIR set to ``path`` for the block, restored after (for session- and module-scoped
    fixtures, where the function-scoped ``isolated_cache`` fixture cannot reach)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("RBCHECK_CACHE_DIR", str(path))
        yield Path(path)


def built_once(tmp_path_factory, name: str, build) -> Path:
    """The directory ``name``, filled by ``build(path)`` once per test run and shared by every test process.

    Under pytest-xdist each worker has its own session, so a session-scoped fixture would build the same
    thing once per worker; here the first worker to ask builds it under an exclusive lock in the run's
    common temporary folder, and the others wait for it and reuse it. Tests must not change what they get
    (copy it first). A build that raised leaves nothing marked built: the next caller tries again.
    """
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        # .../pytest-N, shared by the workers of this run (each has .../pytest-N/popen-gwK)
        root = root.parent
    target, done = root / name, root / f"{name}.built"
    with open(root / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes, also if build raises
        if not done.exists():
            shutil.rmtree(target, ignore_errors=True)  # what a build that raised left behind
            target.mkdir()
            build(target)
            done.touch()
    return target


def result_rows(results_dir: Path) -> list:
    """The rows of ``results_dir/results.csv`` as dicts of strings, without the run-dependent columns:
    two runs of the same sweep must give exactly these, digit for digit."""
    with open(Path(results_dir) / "results.csv", newline="") as fh:
        return [{k: v for k, v in r.items() if k not in RUN_DEPENDENT_COLUMNS} for r in csv.DictReader(fh)]


def file_tree(folder: Path) -> dict:
    """Every file below ``folder``: ``{relative posix path: bytes}``, to show a folder unchanged."""
    folder = Path(folder)
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


#: Engines whose every process compiles its steps first (JAX's XLA: seconds to tens of seconds per function
#: and process), left out of the test suite's own sweeps so that it stays within minutes on 2 cores. Their
#: rows in the baseline are gated by CI's full sweep (.github/workflows/crosscheck.yml, `--require` each)
#: and their conventions and verdicts by their adapter tests
#: (each engine's test_ENGINE_engine.py in tests/cross_checks/engines).
COMPILED_ENGINES = ("jaxsim", "brax", "mjx", "genesis")


def gated_variants() -> list:
    """The available variants of the engines the committed baseline holds (baselines/default), but the
    COMPILED_ENGINES: what the gates, the rerun and whole-engine tests sweep."""
    import json

    from cross_checks.engines import available_variants
    summary = Path(__file__).resolve().parents[2] / "baselines" / "default" / "summary.json"
    engines = {v["name"].split(":", 1)[0] for v in json.loads(summary.read_text())["variants"]}
    return [v for v in available_variants()
            if v.split(":", 1)[0] in engines and v.split(":", 1)[0] not in COMPILED_ENGINES]

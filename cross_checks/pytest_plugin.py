"""rbcheck's pytest plugin (entry point ``pytest11``): the ``assert_engine`` fixture, i.e.
:func:`cross_checks.testing.assert_engine` with a per-session cache (or ``--rbcheck-cache-dir DIR``).
Its options (``--rbcheck-keep-reports``, ``--rbcheck-engine-file``, ``--rbcheck-cache-dir``,
``--rbcheck-jobs``): docs/engines.md. rbcheck itself is imported when the fixture is first used.
Disable the plugin with ``-p no:rbcheck``.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest


def pytest_addoption(parser):
    group = parser.getgroup("rbcheck",
                            "rbcheck: check a rigid-body simulator's declared order (assert_engine)")
    group.addoption("--rbcheck-keep-reports", metavar="DIR", default=None,
                    help="keep each assert_engine sweep's results directory and HTML "
                         "report under DIR/<test>/")
    group.addoption("--rbcheck-engine-file", metavar="FILE", action="append", default=[],
                    help="register this engine file for every assert_engine call (repeatable)")
    group.addoption("--rbcheck-cache-dir", metavar="DIR", default=None,
                    help="run cache shared across sessions (default: a fresh cache per test session)")
    group.addoption("--rbcheck-jobs", metavar="N", type=int, default=None,
                    help="worker processes per assert_engine sweep (default: all cores)")


@pytest.fixture(scope="session")
def rbcheck_cache_dir(pytestconfig, tmp_path_factory) -> Path:
    """The run cache of this test session (``--rbcheck-cache-dir`` or a fresh temporary directory)."""
    given = pytestconfig.getoption("rbcheck_cache_dir")
    return Path(given) if given else tmp_path_factory.mktemp("rbcheck-cache")


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_")[:120] or "test"


@pytest.fixture
def assert_engine(request, rbcheck_cache_dir):
    """``assert_engine(variant, scenarios, *, engine_file=None, invariance=False)`` — see
    cross_checks.testing.assert_engine."""
    cfg = request.config
    keep = cfg.getoption("rbcheck_keep_reports")
    session_files = [Path(f) for f in cfg.getoption("rbcheck_engine_file")]
    jobs = cfg.getoption("rbcheck_jobs")
    calls = []

    def check(variant, scenarios, *, engine_file=None, invariance=False):
        __tracebackhide__ = True   # the user sees the verdict sentences, not rbcheck's frames
        from cross_checks.testing import as_list, run_engine_checks
        calls.append(variant)
        out = None
        if keep:
            out = Path(keep) / _safe(request.node.nodeid) / f"{len(calls)}-{_safe(str(variant))}"
            out.parent.mkdir(parents=True, exist_ok=True)
        return run_engine_checks(variant, scenarios, engine_file=session_files + as_list(engine_file),
                                 out_dir=out, cache_dir=rbcheck_cache_dir, jobs=jobs, invariance=invariance)

    return check

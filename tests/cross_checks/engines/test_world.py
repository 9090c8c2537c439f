"""The World API's worked example (docs/engines.md, examples/python_engine/expmap_engine.py): the page shows
the file as it is, and the engine, registered as any user engine, is swept beside MuJoCo with every verdict
as expected and its runs equal to the reference's scheme it implements (reference:expmap_gyro) to round-off.
The engine contract itself is tests/cross_checks/engines/test_contract.py's (it runs this engine too)."""
import sys
from pathlib import Path

import numpy as np

from cross_checks import engines
from cross_checks.scenario import load_scenario
from tests.helpers import tolerances as tol

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE = ROOT / "examples" / "python_engine" / "expmap_engine.py"


def _engine():
    sys.path.insert(0, str(EXAMPLE.parent))
    try:
        from expmap_engine import ExpmapEngine
    finally:
        sys.path.pop(0)
    return ExpmapEngine()


def test_the_page_shows_the_example_as_it_is_and_it_is_short():
    text = EXAMPLE.read_text(encoding="utf-8")
    assert text in (ROOT / "docs" / "engines.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 80


def test_the_example_is_swept_beside_mujoco_with_every_verdict_as_expected(tmp_path, monkeypatch):
    from cross_checks.sweep import run_sweep
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(engines, "_user", dict(engines._user))
    engines.register_adapter(_engine(), "examples/python_engine/expmap_engine.py")
    scs = [load_scenario(n) for n in ("applied_torque", "projectile")]
    summary = run_sweep(scs, ["expmap:euler", "mujoco:euler"], tmp_path / "r", jobs=1, second_reference=False)
    mine = [r for r in summary["convergence"] if r["engine"] == "expmap:euler"]
    assert mine and all(r["matches_expectation"] for r in mine)
    for sc in scs:   # the scheme it implements, to the round-off of a differently ordered computation
        a = engines.run_variant(sc, "expmap:euler").y
        b = engines.run_variant(sc, "reference:expmap_gyro").y
        assert np.max(np.abs(a - b)) <= tol.EXAMPLE_ENGINE_VS_ITS_SCHEME * max(1.0, np.max(np.abs(b)))


def test_a_host_rows_world_keeps_a_copy_of_the_packed_rows_it_is_set_to():
    """world.HostRowsWorld (Brax's world's base): the rows live on the host between compiled rollouts, so a
    caller changing its array afterwards must not move the bodies; ``ends`` are the requests' steps."""
    from types import SimpleNamespace

    from cross_checks.engines.world import HostRowsWorld
    w = HostRowsWorld([SimpleNamespace(n_steps=4), SimpleNamespace(n_steps=9)])
    assert w.read().shape == (2, 13) and w.ends == [4, 9] and w.host_s == 0.0 and w.rollout_takes_all_forces
    y = np.arange(26, dtype=float).reshape(2, 13)
    w.set_state(y)
    y[:] = -1.0
    assert np.array_equal(w.read(), np.arange(26, dtype=float).reshape(2, 13))

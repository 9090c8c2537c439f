"""reports.data: the indexed look-ups the figures use give what a scan of the file gives.

rows_for and records are answered from indexes built once per loaded directory; each must return
exactly the rows / records (same order) a scan of results.csv / summary.json returns, for every
scenario and variant, and a caller changing the returned list must not change the next answer.
"""
import pytest

from reports.data import load_results
from tests.helpers.sweeps import built_once
from tests.reports.test_browser import _browser_sweep


@pytest.fixture(scope="module")
def res(tmp_path_factory):
    return load_results(built_once(tmp_path_factory, "browser_report", _browser_sweep) / "res")


def test_indexed_rows_and_records_are_the_scanned_ones(res):
    scenarios = [s["name"] for s in res.scenarios] + ["no_such_scenario"]
    assert len(res.rows) > 0
    for sc in scenarios:
        assert res.rows_for(sc) == [r for r in res.rows if r["scenario"] == sc]
        for v in res.variants + ["no:such"]:
            assert res.rows_for(sc, v) == [r for r in res.rows if r["scenario"] == sc and r["engine"] == v]
            for mode, key in (("free_running", "convergence"), ("one_step", "local_convergence")):
                for q in (None, "position", "angular_velocity"):
                    assert res.records(sc, v, q, mode=mode) == [
                        r for r in res.summary.get(key, []) if r["scenario"] == sc and r["engine"] == v
                        and (q is None or r["quantity"] == q)]
    assert res.records() == res.summary["convergence"]
    assert sum(len(res.rows_for(sc)) for sc in scenarios) == len(res.rows)


def test_a_caller_changing_a_returned_list_does_not_change_the_next_answer(res):
    sc = res.scenarios[0]["name"]
    first = res.rows_for(sc)
    first.clear()
    assert res.rows_for(sc) == [r for r in res.rows if r["scenario"] == sc] != []
    recs = res.records(sc)
    recs.clear()
    assert res.records(sc) != []

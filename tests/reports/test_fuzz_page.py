"""The fuzz page is drawn from fuzz.json alone: every counterexample, explanation and engine row shows; a
file that is not a fuzz summary is refused with the field named."""
import json

import pytest

from reports.data import ResultsError
from reports.fuzz_page import render_fuzz

SUMMARY = {
    "format": "rbcheck fuzz summary", "schema_version": 1,
    "provenance": {"started": "2026-01-01T00:00:00+00:00", "seed": 7, "budget_s": 60.0, "jobs": 2,
                   "engines": {"pybullet": {"version": "3.2.7"}}, "batch": 16, "n0_cycle": [8, 16, 32]},
    "variants": ["pybullet:maximal"],
    "cases": {"drawn": 32, "judged": 31, "skipped": 1, "batches": 2, "cached_batches": 1, "search_s": 61.0,
              "wall_s": 80.0, "cases_per_s": 0.5, "case_variant_runs": 31},
    "per_variant": {"pybullet:maximal": {"cases": 31, "seconds": 12.0, "cases_per_s": 2.6,
                                         "properties": {"free_running_order": [100, 24],
                                                        "one_step_order": [124, 0], "conservation": [5, 0],
                                                        "agreement": [0, 0]}}},
    "pairs": {},
    "properties": {"free_running_order": [100, 24], "one_step_order": [124, 0], "conservation": [5, 0],
                   "agreement": [0, 0]},
    "numbers": {"hL": {"min": 0.01, "median": 0.05, "max": 0.2},
                "kinds": {"body": {"tensor": 20, "moments": 11}}},
    "counterexamples": [{"file": "counterexamples/01_x.toml", "property": "free_running_order",
                         "variants": ["pybullet:maximal"], "magnitude": "order 0 where 1 is expected",
                         "cases_with_this_failure": 3, "confirmed_by_sweep": True,
                         "sentence": "pybullet:maximal: angular_velocity does not converge <b>",
                         "explanation": "btMatrix3x3::solve33 threshold", "shrink_steps": ["duration halved"],
                         "also_failed": {"one_step_order": 4},
                         "reproduce": "rbcheck sweep counterexamples/01_x.toml --engines pybullet:maximal"}],
    "not_shrunk": [{"property": "conservation", "variants": ["mujoco:rk4"], "cases": 2, "explained": False,
                    "also_failed": {},
                    "first": {"seed": 7, "index": 9, "sentence": "energy drift 3× its allowance"}}],
    "batch_errors": [{"batch": 3, "error": "ExactError: DOP853 failed"}],
}


def test_the_page_shows_every_counterexample_and_engine_row(tmp_path):
    (tmp_path / "fuzz.json").write_text(json.dumps(SUMMARY))
    html = render_fuzz(tmp_path).read_text()
    for text in ("seed 7", "counterexamples/01_x.toml", "solve33", "pybullet:maximal", "100 / 24",
                 "duration halved", "rbcheck sweep counterexamples/01_x.toml", "ExactError", "h·L",
                 "tensor 20", "2 distinct failure", "also failed: one_step_order on 4 case(s)",
                 "mujoco:rk4: 2 case(s); first: case 9: energy drift"):
        assert text in html, text
    assert "converge &lt;b&gt;" in html and "converge <b>" not in html      # data is escaped


@pytest.mark.parametrize("content, field", [("{", "not valid JSON"), ('{"format": "x"}', "format")])
def test_a_file_that_is_not_a_fuzz_summary_is_refused(tmp_path, content, field):
    (tmp_path / "fuzz.json").write_text(content)
    with pytest.raises(ResultsError, match=field):
        render_fuzz(tmp_path)

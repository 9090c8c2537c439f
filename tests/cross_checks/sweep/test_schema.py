"""summary.json's schema: what sweeps write passes, the committed compact baseline passes for compare and
is refused for the report; each damaged field is named."""
import json

import pytest

from cross_checks.sweep.jobs import SCHEMA_VERSION
from cross_checks.sweep.schema import KNOWN_SCHEMA_VERSION, SchemaError, check_summary
from tests.helpers.repo import BASELINE as BASELINE_DIR

BASELINE = json.loads((BASELINE_DIR / "summary.json").read_text())


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """summary.json (as written) of a small real sweep (no report)."""
    from cross_checks.scenario import load_scenario
    from cross_checks.sweep import run_sweep
    tmp = tmp_path_factory.mktemp("schema")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("RBCHECK_CACHE_DIR", str(tmp / "cache"))
        run_sweep([load_scenario("projectile")], ["reference:course", "reference:rk4"], tmp / "res", jobs=1,
                  progress=False)
    return json.loads((tmp / "res" / "summary.json").read_text())


def test_the_schema_version_read_is_the_one_written():
    assert KNOWN_SCHEMA_VERSION == SCHEMA_VERSION


def test_what_a_sweep_writes_follows_the_schema(swept):
    check_summary(swept, for_report=True)


def test_the_committed_baseline_follows_the_schema_for_compare_and_is_no_report():
    check_summary(BASELINE)
    with pytest.raises(SchemaError, match="summary.form: a compact baseline .* holds no report data"):
        check_summary(BASELINE, for_report=True)


@pytest.mark.parametrize("edit, field", [
    (lambda s: s["scenarios"][0].__setitem__("dt_s", "fast"), "summary.scenarios[0].dt_s: must be a number"),
    (lambda s: s["scenarios"][0].__setitem__("dt_s", -1.0), "summary.scenarios[0].dt_s: must be a positive"),
    (lambda s: s["scenarios"].append(dict(s["scenarios"][0])), "scenario projectile appears twice"),
    (lambda s: s["convergence"][3].__setitem__("quantity", "speed"),
     "summary.convergence[3].quantity: must be one of"),
    (lambda s: s["convergence"][3].pop("assessment"), "summary.convergence[3].assessment: missing"),
    (lambda s: s["convergence"][3].__setitem__("order", float("inf")),
     "summary.convergence[3].order: must be a finite"),
    (lambda s: s["convergence"][3].__setitem__("matches_expectation", "yes"),
     "matches_expectation: must be true or false"),
    (lambda s: s["variants"][0].__setitem__("name", 7), "summary.variants[0].name: must be a string"),
    (lambda s: s.__setitem__("schema_version", True), "summary.schema_version: must be a whole number"),
    (lambda s: s.__setitem__("schema_version", 0), "summary.schema_version: 0 is not a results schema"),
])
def test_each_damaged_field_is_named(swept, edit, field):
    s = json.loads(json.dumps(swept))
    edit(s)
    with pytest.raises(SchemaError, match=field.replace("[", r"\[").replace("]", r"\]")):
        check_summary(s, for_report=True)

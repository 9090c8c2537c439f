"""Random and mutated scenario files: the only outcomes are a valid Scenario / a
run, or exit 2 with a message."""
import os
import re

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cross_checks.cli import main
from cross_checks.scenario import ScenarioError, catalog_names, catalog_path, parse_scenario

CATALOG_TEXTS = [catalog_path(n).read_text() for n in catalog_names()]
NUMBER = re.compile(r"-?\d+(\.\d+)?(e-?\d+)?")
TOKENS = ["nan", "inf", "-inf", "-1.0", "0", "0.0", "1e308", "1e-308", "-1e308", '"x"', "[]", "[1.0]",
          "[[1.0]]", "true", "{}", "[1, 2, 3, 4, 5]", "1e-320", '""', "[nan, 0, 0]", "[0.0, 0.0, 0.0, 0.0]"]


@st.composite
def mutated_scenario(draw):
    text = draw(st.sampled_from(CATALOG_TEXTS))
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["number", "delete_line", "duplicate_line",
                                     "truncate", "insert", "key_typo"]))
        lines = text.splitlines()
        if kind == "number":
            spans = [m.span() for m in NUMBER.finditer(text)]
            if spans:
                a, b = draw(st.sampled_from(spans))
                text = text[:a] + draw(st.sampled_from(TOKENS)) + text[b:]
        elif kind == "delete_line" and lines:
            i = draw(st.integers(0, len(lines) - 1))
            text = "\n".join(lines[:i] + lines[i + 1:])
        elif kind == "duplicate_line" and lines:
            i = draw(st.integers(0, len(lines) - 1))
            text = "\n".join(lines[:i + 1] + lines[i:])
        elif kind == "truncate":
            text = text[:draw(st.integers(0, len(text)))]
        elif kind == "insert":
            i = draw(st.integers(0, len(text)))
            text = text[:i] + draw(st.text(max_size=8)) + text[i:]
        elif kind == "key_typo":
            keys = re.findall(r"^(\w+) =", text, flags=re.M)
            if keys:
                k = draw(st.sampled_from(keys))
                text = text.replace(f"{k} =", f"{k}x =", 1)
    return text


@settings(max_examples=int(os.environ.get("RBCHECK_FUZZ_EXAMPLES", 300)), deadline=None,
          suppress_health_check=[HealthCheck.too_slow],
          derandomize=not os.environ.get("RBCHECK_FUZZ_EXAMPLES"))
@given(mutated_scenario())
def test_loader_accepts_or_rejects_with_a_located_message(text):
    try:
        sc = parse_scenario(text, "fuzz.toml")
    except ScenarioError as exc:
        assert str(exc).startswith("fuzz.toml: ")
        assert len(str(exc)) < 400 and "\n" not in str(exc).strip()
        return
    assert sc.problem.body.mass_kg > 0 and 0 < sc.dt_s <= sc.duration_s


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(text=mutated_scenario())
def test_cli_run_gives_a_run_or_exit_2(tmp_path, capsys, text):
    path = tmp_path / "fuzz.toml"
    path.write_text(text)
    out = tmp_path / "out.csv"
    out.unlink(missing_ok=True)
    rc = main(["run", str(path), "--engine", "reference:course",
               "--dt", "0.01", "--duration", "0.05", "--out", str(out)])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if rc == 2:
        assert err.startswith("rbcheck run: error: ") and err.count("\n") == 1, err
        assert not out.exists()
    elif rc == 1:
        assert "diverged at t = " in err and out.exists()
    else:
        assert rc == 0 and out.exists()


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=300))
def test_random_text_never_crashes_the_loader(text):
    try:
        parse_scenario(text, "random.toml")
    except ScenarioError:
        pass

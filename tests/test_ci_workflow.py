"""The CI workflow parses and runs exactly the README's commands; .ci/run runs the README's test command."""
import re
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]


def readme_commands():
    blocks = re.findall(r"```bash\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    main_cmd, test_cmd = blocks[0].strip(), blocks[1].strip()
    assert "rbcheck sweep" in main_cmd and "pytest" in test_cmd
    return main_cmd, test_cmd


def _runs(job):
    return [s.get("run", "") for s in job["steps"]]


def test_workflow_parses_and_uses_the_readme_commands():
    wf = yaml.safe_load((ROOT / ".github/workflows/crosscheck.yml").read_text())
    main_cmd, test_cmd = readme_commands()
    assert test_cmd in _runs(wf["jobs"]["tests"])
    steps = wf["jobs"]["crosscheck"]["steps"]
    runs = _runs(wf["jobs"]["crosscheck"])
    # on a fresh runner: the README's main command as a newcomer runs it (and the CI formats after it)
    assert runs[0] == "" and any(r == main_cmd or r.startswith(main_cmd + " --junit ") for r in runs)
    out = re.search(r"rbcheck sweep .*--out (\S+)", main_cmd)[1]
    # the main command's results are compared as they are (Drake absent: one line, exit 0) ...
    assert any(r.startswith(f".venv/bin/rbcheck compare baselines/default {out} ") for r in runs)
    # ... and the baseline's optional engines' rows are gated by a sweep with them, compared with --require
    full = [r for r in runs if 'pip install -q -e ".[drake,engines]"' in r and "rbcheck sweep" in r]
    assert full, "no sweep with Drake"
    full_out = re.search(r"rbcheck sweep .*--out (\S+)", full[0])[1]
    # CI's full sweep runs the invariance checks (issue 46; docs/invariance.md "In CI")
    assert " --invariance " in full[0]
    compare = [r for r in runs if f"rbcheck compare baselines/default {full_out}" in r]
    assert compare
    import json
    made = json.loads((ROOT / "baselines" / "default" / "summary.json").read_text())
    optional = {v["name"].split(":", 1)[0] for v in made["variants"]} - {"reference", "mujoco", "pybullet"}
    assert optional, "the baseline holds no optional engine"
    for engine in optional:   # every optional engine of the baseline is installed by the sweep and required
        assert f"--require {engine}" in compare[0], engine
    assert "--markdown" in compare[0]
    # the CI formats (issue 44): every sweep and compare writes JUnit XML and annotates the run; each appends
    # its own markdown to the job summary ($GITHUB_STEP_SUMMARY), so no step copies it there by hand
    gates = [r for r in runs if "rbcheck sweep" in r or "rbcheck compare" in r]
    junit = [re.search(r"--junit (\S+)", r) for r in gates]
    assert len(gates) == 4 and all(junit) and all("--github-annotations" in r for r in gates)
    assert len({m[1] for m in junit}) == 4
    assert not any("GITHUB_STEP_SUMMARY" in r for r in runs)
    # the full results (report and summary.json) and their compact baseline are uploaded as artifacts
    uploaded = [s["with"]["path"] for s in steps if s.get("uses", "").startswith("actions/upload-artifact")]
    import fnmatch
    assert all(any(fnmatch.fnmatch(m[1], p) for p in uploaded) for m in junit), "a JUnit file not uploaded"
    baseline = [r.split() for r in runs if "rbcheck baseline" in r]
    assert full_out in uploaded and baseline and baseline[0][-2] == full_out and baseline[0][-1] in uploaded


def test_the_baseline_holds_the_engines_ci_requires():
    import json
    made = json.loads((ROOT / "baselines" / "default" / "summary.json").read_text())
    engines = {v["name"].split(":", 1)[0] for v in made["variants"]}
    assert {"reference", "mujoco", "pybullet", "drake", "dart", "jaxsim", "brax", "mjx"} <= engines


INTEGRATION = ".venv/bin/python -m pytest -n 2 -m integration"


def test_ci_run_runs_the_readme_test_command_then_the_integration_tests_it_leaves_out():
    _, test_cmd = readme_commands()
    lines = [ln.strip() for ln in (ROOT / ".ci/run").read_text().splitlines()]
    assert test_cmd in lines and INTEGRATION in lines
    assert lines.index(test_cmd) < lines.index(INTEGRATION)
    # the README's command leaves them (and the slow studies) out, the second invocation runs exactly them
    import tomllib
    opts = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    assert "-m 'not slow and not integration'" in opts["addopts"]
    assert any(m.startswith("integration:") for m in opts["markers"])
    assert "-m integration" in (ROOT / "README.md").read_text()


def test_the_workflow_runs_the_integration_tests_after_the_readme_test_command():
    wf = yaml.safe_load((ROOT / ".github/workflows/crosscheck.yml").read_text())
    _, test_cmd = readme_commands()
    runs = _runs(wf["jobs"]["tests"])
    assert INTEGRATION in runs and runs.index(test_cmd) < runs.index(INTEGRATION)

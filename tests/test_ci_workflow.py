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


def test_workflow_parses_and_uses_the_readme_commands():
    wf = yaml.safe_load((ROOT / ".github/workflows/crosscheck.yml").read_text())
    steps = wf["jobs"]["crosscheck"]["steps"]
    runs = [s.get("run", "") for s in steps]
    main_cmd, test_cmd = readme_commands()
    assert test_cmd in runs and main_cmd in runs
    assert runs.index(test_cmd) < runs.index(main_cmd)
    compare = [r for r in runs if "rbcheck compare baselines/" in r]
    assert compare and "--markdown" in compare[0]
    assert any("GITHUB_STEP_SUMMARY" in r for r in runs)
    # the full results (report and summary.json) and their compact baseline are uploaded as artifacts
    out = re.search(r"rbcheck sweep .*--out (\S+)", main_cmd)[1]
    uploaded = [s["with"]["path"] for s in steps if s.get("uses", "").startswith("actions/upload-artifact")]
    baseline = [r.split() for r in runs if "rbcheck baseline" in r]
    assert out in uploaded and baseline and baseline[0][-2] == out and baseline[0][-1] in uploaded


def test_ci_run_runs_the_readme_test_command():
    _, test_cmd = readme_commands()
    assert test_cmd in (ROOT / ".ci/run").read_text()

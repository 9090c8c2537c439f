"""docs/cli.md's exit-code table covers every command, and each command's exit 2 is one line."""
import re
from pathlib import Path

import pytest

from cross_checks import cli

README = (Path(__file__).resolve().parents[1] / "docs" / "cli.md").read_text()


def _table():
    rows = {}
    for line in README.splitlines():
        m = re.match(r"^\| `(\w+)` \|(.*)\|$", line)
        if m:
            rows[m[1]] = [c.strip() for c in m[2].split("|")]
    return rows


def test_the_table_lists_every_command_with_every_exit_code():
    rows = _table()
    assert set(rows) == set(cli.COMMANDS)
    header = next(line for line in README.splitlines() if line.startswith("| command |"))
    assert [c.strip() for c in header.strip("|").split("|")] == ["command", "0", "1", "2", "130 / 143"]
    assert all(len(cells) == 4 and cells[2] for cells in rows.values())


BAD = {
    "list": ["list"],  # takes no input: its exit 2 is an unexpected error, planted below
    "run": ["run", "projectile", "--engine", "reference:nope", "--out", "{tmp}/t.csv"],
    "sweep": ["sweep", "projectile", "--out", ""],
    "show": ["show", "projectile", "--dt", "2.0"],
    "report": ["report", "{tmp}/missing"],
    "check": ["check", "{tmp}/missing.csv", "--scenario", "projectile"],
    "compare": ["compare", "{tmp}/missing", "{tmp}/missing"],
    "baseline": ["baseline", "{tmp}/missing", "{tmp}/out"],
    "bench": ["bench", "--json", "{tmp}/no/such/dir/b.json"],
    "fuzz": ["fuzz", "--engines", "reference:nope", "--out", "{tmp}/fz"],
    "repro": ["repro", "mujoco:rk4", "projectile", "--claim", "wobble", "--out", "{tmp}/r.py"],
}


@pytest.mark.parametrize("command", sorted(cli.COMMANDS))
def test_exit_2_of_every_command_is_one_line(command, tmp_path, capsys, monkeypatch):
    argv = BAD[command]
    if command == "list":
        import cross_checks.engines as engines
        monkeypatch.setattr(engines, "all_variants", lambda: 1 / 0)
    assert cli.main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"rbcheck {command}: error: ") and err.count("\n") == 1 and "Traceback" not in err


def test_exit_0_and_1_of_compare_as_the_table_says(tmp_path, capsys):
    base = str(Path(__file__).resolve().parents[1] / "baselines" / "default")
    assert cli.main(["compare", base, base]) == 0
    assert "OK: no regression" in capsys.readouterr().out

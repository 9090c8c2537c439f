"""Randomly damaged results directories given to `rbcheck report` and `rbcheck compare`: the only
outcomes are exit 0/1 (report: 0) or exit 2 with one line — never a traceback — and nothing is ever
written outside the directory (hostile scenario names such as ../../x or /tmp/x included)."""
import json
import os
import shutil
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cross_checks.cli import main

EXAMPLES = int(os.environ.get("RBCHECK_FUZZ_EXAMPLES", 0))
# fixed: xdist workers must collect the same ids
OUTSIDE = Path(tempfile.gettempdir()) / "rbcheck-fuzz-escape-target"
HOSTILE_NAMES = ["../../x", "../escaped", str(OUTSIDE), "a\x00b", "x" * 300, "", ".", "..", "plots/../../y",
                 "scenario-../../z", "<script>"]
TOKENS = ["", "nan", "inf", "-inf", "-1", "1e308", "oops", "true", "../../x", "\x00", "ok", "diverged", "0",
          "x" * 500, '"', ","] + HOSTILE_NAMES
JSON_VALUES = st.recursive(st.none() | st.booleans() | st.integers(-10, 10) | st.floats(allow_nan=True)
                           | st.sampled_from(HOSTILE_NAMES), lambda c: st.lists(c, max_size=3)
                           | st.dictionaries(st.text(max_size=5), c, max_size=3), max_leaves=6)

@pytest.fixture
def made(tiny_results):
    return tiny_results


def _paths(obj, path=()):
    yield path
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, path + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _paths(v, path + (i,))


def _slot(obj, path):
    """``(container, key)`` of ``path`` in ``obj`` as it is now (earlier edits
    may have changed it), or None."""
    parent = obj
    for k in path[:-1]:
        if (isinstance(parent, dict) and k in parent
                or isinstance(parent, list) and isinstance(k, int) and k < len(parent)):
            parent = parent[k]
        else:
            return None
    k = path[-1]
    ok = (isinstance(parent, dict) and k in parent) or (isinstance(parent, list) and isinstance(k, int)
                                                        and k < len(parent))
    return (parent, k) if ok else None


def _damage_json(d: Path, draw):
    sj = d / "summary.json"
    obj = json.loads(sj.read_text())
    paths = [p for p in _paths(obj) if p]
    for _ in range(draw(st.integers(1, 3))):
        slot = _slot(obj, draw(st.sampled_from(paths)))
        if slot is None:
            continue
        parent, k = slot
        if isinstance(parent, dict) and draw(st.booleans()):
            del parent[k]
        else:
            parent[k] = draw(JSON_VALUES)
    sj.write_text(json.dumps(obj))


def _damage_csv(d: Path, draw):
    rc = d / "results.csv"
    lines = rc.read_text().splitlines()
    kind = draw(st.sampled_from(["cell", "cell", "drop_column", "duplicate_row", "drop_line", "extra_cell"]))
    i = draw(st.integers(0, len(lines) - 1))
    cells = lines[i].split(",")
    if kind == "cell":
        cells[draw(st.integers(0, len(cells) - 1))] = draw(st.sampled_from(TOKENS))
        lines[i] = ",".join(cells)
    elif kind == "drop_column":
        j = draw(st.integers(0, len(lines[0].split(",")) - 1))
        lines = [",".join(c for k, c in enumerate(line.split(",")) if k != j) for line in lines]
    elif kind == "duplicate_row":
        lines.append(lines[max(i, 1) if len(lines) > 1 else 0])
    elif kind == "drop_line":
        del lines[i]
    else:
        lines[i] += ",surplus"
    rc.write_text("\n".join(lines) + "\n")


def _damage_bytes(p: Path, draw):
    data = bytearray(p.read_bytes())
    if not data:
        return
    if draw(st.booleans()):
        p.write_bytes(bytes(data[: draw(st.integers(0, len(data) - 1))]))
    else:
        k = draw(st.integers(0, len(data) - 1))
        data[k] ^= 1 << draw(st.integers(0, 7))
        p.write_bytes(bytes(data))


def _rename_scenario(d: Path, draw):
    """A tampered name in both files, as a hostile user would write it."""
    name = draw(st.sampled_from(HOSTILE_NAMES))
    sj = d / "summary.json"
    obj = json.loads(sj.read_text())
    text = json.dumps(obj).replace('"tiny"', json.dumps(name))
    sj.write_text(text)
    rc = d / "results.csv"
    rc.write_text(rc.read_text().replace("tiny,", (name if "," not in name else f'"{name}"') + ",", ))


@st.composite
def damage(draw):
    ops = draw(st.lists(st.sampled_from(["json", "csv", "bytes", "delete", "rename"]),
                        min_size=1, max_size=3))
    seed = draw(st.integers(0, 2 ** 16))
    return ops, seed, draw


def _apply(d: Path, ops, draw):
    for op in ops:
        files = sorted(p for p in d.rglob("*") if p.is_file())
        if op == "json" and (d / "summary.json").is_file():
            try:
                _damage_json(d, draw)
            except ValueError:
                pass
        elif op == "csv" and (d / "results.csv").is_file():
            _damage_csv(d, draw)
        elif op == "bytes" and files:
            _damage_bytes(draw(st.sampled_from(files)), draw)
        elif op == "delete" and files:
            draw(st.sampled_from(files)).unlink()
        elif op == "rename" and (d / "summary.json").is_file() and (d / "results.csv").is_file():
            try:
                _rename_scenario(d, draw)
            except ValueError:
                pass


def _snapshot(root: Path, skip: Path):
    return {p for p in root.rglob("*") if skip not in p.parents and p != skip}


def _check_outcome(rc, err, allowed, command):
    assert "Traceback" not in err, err
    assert rc in allowed, (rc, err)
    if rc == 2:
        assert err.startswith(f"rbcheck {command}: error: ") and err.count("\n") == 1, err


def _fuzz(made, data, command):
    ops, _seed, _ = data.draw(damage())
    root = Path(tempfile.mkdtemp(prefix="rbcheck-fuzz-"))
    try:
        d = root / "res"
        shutil.copytree(made, d)
        _apply(d, ops, data.draw)
        before = _snapshot(root, d)
        import contextlib
        import io
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            if command == "report":
                rc = main(["report", str(d), "--jobs", "1"])
            else:
                rc = main(["compare", str(made), str(d)] if data.draw(st.booleans())
                          else ["compare", str(d), str(made)])
        _check_outcome(rc, err.getvalue(), (0, 2) if command == "report" else (0, 1, 2), command)
        assert _snapshot(root, d) == before  # nothing written beside the directory
        assert not OUTSIDE.exists() and not (root.parent / "escaped").exists()
    finally:
        shutil.rmtree(root, ignore_errors=True)


@settings(max_examples=EXAMPLES or 30, deadline=None, derandomize=not EXAMPLES,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_compare_of_a_damaged_directory_exits_0_1_or_2_in_one_line(made, data):
    _fuzz(made, data, "compare")


@settings(max_examples=EXAMPLES or 3, deadline=None, derandomize=not EXAMPLES,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_report_of_a_damaged_directory_exits_0_or_2_and_writes_only_inside(made, data):
    _fuzz(made, data, "report")


@pytest.mark.parametrize("name", [pytest.param(n, marks=[] if n == str(OUTSIDE) else [pytest.mark.slow])
                                  for n in HOSTILE_NAMES])
def test_report_with_a_hostile_scenario_name_writes_only_inside(made, tmp_path, name, capsys):
    d = tmp_path / "res"
    shutil.copytree(made, d)
    text = (d / "summary.json").read_text().replace('"tiny"', json.dumps(name))
    (d / "summary.json").write_text(text)
    csv_name = f'"{name}"' if "," in name or '"' in name else name
    (d / "results.csv").write_text((d / "results.csv").read_text().replace("tiny,", csv_name + ","))
    before = _snapshot(tmp_path, d)
    rc = main(["report", str(d), "--jobs", "1"])
    _check_outcome(rc, capsys.readouterr().err, (0, 2), "report")
    assert _snapshot(tmp_path, d) == before and not OUTSIDE.exists()
    for p in d.rglob("*"):
        assert p.resolve().is_relative_to(d.resolve())

"""Terminal escape injection (issue 45): text from a results directory someone sent, an engine file or a
command's stderr reaches the terminal, markdown and HTML with its control characters shown as ``\\x1b``."""
import json
import shutil

from cross_checks.cli import main
from cross_checks.core.progress import shown

#: What a forged baseline carries: erase the line, go back to its start, and print a verdict of its own.
FORGED = "9.9\x1b[2K\r\x1b[32mOK: no regression\x1b[0m"


def test_control_characters_are_shown_escaped_newlines_and_tabs_kept():
    assert shown("a\x1b[31mb\rc\x00d\x7f\x9b\ne\tf") == "a\\x1b[31mb\\x0dc\\x00d\\x7f\\x9b\ne\tf"
    assert shown("Δt = 0.01 s — ω") == "Δt = 0.01 s — ω"


def test_compare_shows_a_forged_provenance_escaped_on_the_terminal_and_in_markdown(tiny_results, tmp_path,
                                                                                   capsys):
    base, new = tmp_path / "base", tmp_path / "new"
    shutil.copytree(tiny_results, base)
    shutil.copytree(tiny_results, new)
    summary = json.loads((base / "summary.json").read_text())
    summary["provenance"]["numpy"] = FORGED
    (base / "summary.json").write_text(json.dumps(summary))
    md = tmp_path / "compare.md"
    main(["compare", str(base), str(new), "--markdown", str(md)])
    out, err = capsys.readouterr()
    assert "9.9" in out + err   # the version difference is reported...
    assert "\x1b" not in out + err and "\r" not in out + err   # ...escaped
    assert "\\x1b[2K\\x0d" in out + err
    assert "\x1b" not in md.read_text() and "\\x1b[2K" in md.read_text()


def test_the_report_shows_a_forged_provenance_escaped_in_html(tiny_results, tmp_path):
    import reports
    res = tmp_path / "res"
    shutil.copytree(tiny_results, res)
    summary = json.loads((res / "summary.json").read_text())
    summary["provenance"]["numpy"] = FORGED
    (res / "summary.json").write_text(json.dumps(summary))
    reports.render(res, jobs=1)
    page = (res / "index.html").read_text()
    assert "\x1b" not in page and "\\x1b[2K\\x0d" in page

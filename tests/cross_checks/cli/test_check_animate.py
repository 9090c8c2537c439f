"""`rbcheck check --animate`: a correct tennis_racket file gives a GIF of 30–400 frames that differ; an
unknown extension or an MP4 without ffmpeg is bad input (exit 2, one line naming what is missing and that
GIF works, nothing written); a trajectory that diverged is animated up to its divergence and its last frame
says so."""
import numpy as np
import pytest
from PIL import Image

from cross_checks.cli import main
from cross_checks.engines import run_variant
from cross_checks.scenario import load_scenario
from tests.helpers.repo import ROOT

SC = load_scenario("tennis_racket")


@pytest.fixture(scope="module")
def correct_csv(tmp_path_factory):
    p = tmp_path_factory.mktemp("anim") / "rk4.csv"
    p.write_text(run_variant(SC, "reference:rk4", 0.005, SC.duration_s).to_csv_text(), encoding="utf-8")
    return p


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    """tennis_racket cut to 0.5 s (its scenario file with that duration) and its reference:rk4 run at
    Δt = 0.005 s: 101 rows, for the tests of a format (drawn at FEW_FRAMES) or of a divergence (every row
    before it a frame), which need frames, not the 10 s run (the GIF test keeps it: its 2001 rows the cap
    must bring down)."""
    from cross_checks.scenario import parse_scenario
    folder = tmp_path_factory.mktemp("anim_short")
    toml = folder / "tennis_racket_short.toml"
    catalog = ROOT / "cross_checks" / "scenario" / "catalog" / "tennis_racket.toml"
    text = catalog.read_text(encoding="utf-8").replace("duration = 10.0", "duration = 0.5", 1)
    assert "duration = 0.5" in text
    toml.write_text(text, encoding="utf-8")
    csv = folder / "rk4.csv"
    csv.write_text(run_variant(parse_scenario(text, str(toml)), "reference:rk4", 0.005).to_csv_text(),
                   encoding="utf-8")
    return toml, csv


def _frames(path):
    out = []
    with Image.open(path) as im:
        for k in range(im.n_frames):
            im.seek(k)
            out.append(np.asarray(im.convert("RGB"), dtype=np.int16))
    return out


#: The frame cap of these tests (reports.animation.MAX_FRAMES, 200, patched): each frame is a matplotlib
#: draw and an encode (about 70 ms), and what is tested is that the writer caps a long run's rows at the cap
#: and draws what moves, not the cap's value (tests/reports/test_animation.py: 30 <= MAX_FRAMES <= 400, and
#: frame_indices uniform in time under it).
FEW_FRAMES = 40

#: The MP4 and WebM tests: that ffmpeg wrote a file of frames, not how many (the GIF test counts them)
FFMPEG_FRAMES = 16


@pytest.fixture
def few_frames(monkeypatch):
    import reports.animation
    monkeypatch.setattr(reports.animation, "MAX_FRAMES", FEW_FRAMES)
    return FEW_FRAMES


def test_a_correct_file_animates_to_a_gif_of_frames_that_differ(correct_csv, tmp_path, capsys, few_frames):
    out = tmp_path / "out.gif"
    assert main(["check", str(correct_csv), "--scenario", "tennis_racket", "--animate", str(out)]) == 0
    err = capsys.readouterr().err
    assert f"animation -> {out}" in err and "frames, one every" in err
    frames = _frames(out)
    assert len(frames) == few_frames      # the 10 s run's 2001 rows brought down to the cap
    # the body turns: frames a quarter of the run apart differ in many pixels
    q = len(frames) // 4
    for a, b in ((0, q), (q, 2 * q), (2 * q, 3 * q)):
        assert np.mean(np.any(frames[a] != frames[b], axis=2)) > 0.01
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.gif"]     # no temporary file left


@pytest.mark.parametrize("name, words", [("out.avi", "unknown format '.avi'"), ("out", "unknown format"),
                                         ("out.mp4", "needs ffmpeg")])
def test_bad_formats_are_one_line_exit_2_and_nothing_written(correct_csv, tmp_path, capsys, monkeypatch,
                                                            name, words):
    from matplotlib import animation
    real = animation.writers.is_available
    monkeypatch.setattr(animation.writers, "is_available", lambda w: False if w == "ffmpeg" else real(w))
    out = tmp_path / name
    assert main(["check", str(correct_csv), "--scenario", "tennis_racket", "--animate", str(out)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and ".gif" in lines[0], lines
    assert captured.out == ""                         # refused before any work
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("suffix", [".mp4", ".webm"])
def test_an_mp4_or_webm_is_written_where_ffmpeg_is_installed(short, tmp_path, suffix, monkeypatch):
    from matplotlib import animation

    import reports.animation
    monkeypatch.setattr(reports.animation, "MAX_FRAMES", FFMPEG_FRAMES)
    if not animation.writers.is_available("ffmpeg"):
        pytest.skip("ffmpeg is not installed here (MP4/WebM need it; the GIF path is tested above)")
    out = tmp_path / f"out{suffix}"
    assert main(["check", str(short[1]), "--scenario", str(short[0]), "--animate", str(out)]) == 0
    assert out.stat().st_size > 10_000, out.stat().st_size
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]


def test_a_pose_less_file_is_bad_input(tmp_path, capsys):
    text = run_variant(load_scenario("projectile"), "reference:rk4", 0.01).to_csv_text()
    head, *rows = text.splitlines()
    keep = [i for i, c in enumerate(head.split(",")) if c in ("t", "x", "y", "z", "vx", "vy", "vz")]
    src = tmp_path / "pos.csv"
    src.write_text("\n".join(",".join(line.split(",")[i] for i in keep) for line in [head, *rows]) + "\n")
    out = tmp_path / "out.gif"
    assert main(["check", str(src), "--scenario", "projectile", "--animate", str(out)]) == 2
    assert "no orientation columns" in capsys.readouterr().err
    assert not out.exists()


def test_a_diverged_file_animates_up_to_its_divergence_and_says_so(short, tmp_path, capsys):
    head, *rows = short[1].read_text(encoding="utf-8").splitlines()
    cut = len(rows) // 2
    cols = head.split(",")
    bad = []
    for line in rows[cut:]:
        cells = line.split(",")
        cells[cols.index("wx")] = "nan"
        bad.append(",".join(cells))
    src = tmp_path / "diverged.csv"
    src.write_text("\n".join([head, *rows[:cut], *bad]) + "\n", encoding="utf-8")
    out = tmp_path / "d.gif"
    assert main(["check", str(src), "--scenario", str(short[0]), "--animate", str(out)]) == 1
    assert "diverged at t = 0.25 s: animated up to there" in capsys.readouterr().err
    frames = _frames(out)
    assert len(frames) == cut    # every row before the divergence (t = 0 ... 0.245 s), and none after

    def red(f):   # the dark red of the divergence message (the FAIL label is dark red too, but small)
        return int(np.sum((f[..., 0] > 110) & (f[..., 0] < 170) & (f[..., 1] < 40) & (f[..., 2] < 40)))
    assert red(frames[-1]) > 3 * red(frames[0]) + 200

"""Progress that reaches a CI log: a plain line every few seconds without a terminal, a bar in one."""
import io
import os
import re
import subprocess
import sys

from cross_checks.core.progress import LINE_INTERVAL_S, Progress, stage


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


class Flushed(io.StringIO):
    """A stream that records what had been flushed when each line arrived (a CI log sees only that)."""

    def __init__(self):
        super().__init__()
        self.flushed = ""

    def flush(self):
        self.flushed = self.getvalue()


def test_without_a_terminal_a_line_every_interval_and_a_last_one():
    clock, out = Clock(), Flushed()
    with Progress("rbcheck sweep", "runs", 100, stream=out, tty=False, clock=clock) as p:
        for i in range(100):
            clock.t += 0.5  # 50 s in all: a line at most every LINE_INTERVAL_S
            p.update(1, f"job {i}")
    lines = out.getvalue().splitlines()
    # every interval before the end, plus the last line
    assert len(lines) == int(50 / LINE_INTERVAL_S) - 1 + 1
    assert lines[0] == "rbcheck sweep: runs 10/100 (10%) in 5 s, ~45 s left; last: job 9"
    assert lines[-1] == "rbcheck sweep: runs 100/100 (100%) in 50 s, done"
    assert out.flushed == out.getvalue()  # each line flushed as written


def test_nothing_is_printed_between_intervals_nor_when_the_stage_is_stopped():
    """An interrupted sweep's stderr is its one line (exit 130): the stopped stage adds nothing."""
    clock, out = Clock(), Flushed()
    try:
        with Progress("rbcheck sweep", "runs", 10, stream=out, tty=False, clock=clock) as p:
            clock.t += LINE_INTERVAL_S / 2
            p.update(3)
            raise KeyboardInterrupt
    except KeyboardInterrupt:
        pass
    assert out.getvalue() == ""


def test_the_time_left_follows_the_work_done_not_the_count():
    """Longest first: after the first of 10 items, 90 % of the work is done (counting would say 10 %)."""
    clock, out = Clock(), Flushed()
    with Progress("rbcheck sweep", "runs", 10, stream=out, tty=False, clock=clock, total_work=100.0) as p:
        clock.t += 9.0
        p.update(1, "the longest", work=90.0)
    assert (out.getvalue().splitlines()[0]
            == "rbcheck sweep: runs 1/10 (10%) in 9 s, ~1 s left; last: the longest")


def _left_s(line):
    return float(re.search(r"~(\d+) s left", line)[1])


def test_many_short_runs_after_the_long_ones_are_not_0_s_left():
    """Issue 44, point 7: longest first, 2 s per run beside 0.01 s per step of work. After the long runs
    the work is nearly done but 30 short runs (60 s) are left: the estimate says so, not "~0 s"."""
    clock, out = Clock(), Flushed()
    works = [1000.0] * 10 + [1.0] * 60
    with Progress("rbcheck sweep", "runs", len(works), stream=out, tty=False, clock=clock,
                  total_work=sum(works), interval_s=1e9) as p:
        for i, w in enumerate(works[:40]):
            clock.t += 2.0 + 0.01 * w
            p.update(1, f"run {i}", work=w)
        p._line(clock())   # the line the next interval would print
    truth = sum(2.0 + 0.01 * w for w in works[40:])
    assert _left_s(out.getvalue().splitlines()[0]) == round(truth)


def test_a_slow_first_item_is_not_multiplied_by_every_item_left():
    """Issue 44, point 7: the report's first figure takes 30 s (imports), the others 0.1 s each: half-way
    the estimate is the 0.1 s per figure left, not 30 s x the count ("~8.8 min left", done 1 s later)."""
    clock, out = Clock(), Flushed()
    with Progress("rbcheck report", "figures", 100, stream=out, tty=False, clock=clock, interval_s=1e9) as p:
        clock.t += 30.0
        p.update(1)
        for _ in range(49):
            clock.t += 0.1
            p.update(1)
        p._line(clock())
    assert _left_s(out.getvalue().splitlines()[0]) == round(50 * 0.1)


def test_a_count_alone_gives_no_estimate_before_it_can_tell_the_start_up_from_the_items():
    """The report's first figure took 12 s (imports), the next 76 take 0.1 s each: after one or two figures a
    line says how far it is, not "~7.2 min left" (the start-up times every figure left); from the third on,
    the fitted estimate."""
    clock, out = Clock(), Flushed()
    with Progress("rbcheck report", "figures", 77, stream=out, tty=False, clock=clock, interval_s=1e9) as p:
        clock.t += 12.0
        p.update(1, "first")
        p._line(clock())
        clock.t += 0.1
        p.update(1, "second")
        p._line(clock())
        for _ in range(8):
            clock.t += 0.1
            p.update(1)
        p._line(clock())
    lines = out.getvalue().splitlines()
    assert lines[0] == "rbcheck report: figures 1/77 (1%) in 12 s; last: first"
    assert "left" not in lines[1]
    assert _left_s(lines[2]) == round(67 * 0.1)


def test_in_a_terminal_a_bar_and_no_log_lines():
    out = io.StringIO()
    with Progress("rbcheck sweep", "runs", 3, stream=out, tty=True) as p:
        for _ in range(3):
            p.update(1, "x")
    text = out.getvalue()
    assert "\r" in text and "3/3" in text and "in 0 s" not in text


def test_disabled_prints_nothing():
    out = io.StringIO()
    with Progress("rbcheck sweep", "runs", 3, stream=out, enabled=False) as p:
        p.update(3)
    stage("rbcheck sweep", "writing", enabled=False, stream=out)
    assert out.getvalue() == ""


def test_a_sweep_piped_to_a_log_reports_every_stage(tmp_path):
    """`rbcheck sweep` with stderr a pipe (a CI job): the references, the runs and the results files each
    leave a line on stdout; no terminal control characters."""
    env = {**os.environ, "RBCHECK_CACHE_DIR": str(tmp_path / "cache"), "MPLBACKEND": "Agg"}
    p = subprocess.run([sys.executable, "-m", "cross_checks.cli", "sweep", "projectile", "--engines",
                        "reference:course", "--out", str(tmp_path / "r"), "--jobs", "1"],
                       capture_output=True, text=True, env=env, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stderr == ""  # stderr is for errors: an error or Ctrl-C stays one line there
    err = p.stdout
    assert "rbcheck sweep: references 1/1 (100%) in" in err and "done" in err
    assert re.search(r"^rbcheck sweep: runs (\d+)/\1 \(100%\) in \d+ s, done$", err, re.M)
    assert "rbcheck sweep: writing results.csv" in err
    assert "\r" not in err and "\x1b" not in err

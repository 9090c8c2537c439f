"""cross_checks.core.processes: a command under a supervisor and a time limit (its output tail kept, its
strays killed, a program that cannot start said as Popen says it), processes stopped (one that ignores
SIGTERM killed), and whether the process that left a name behind is gone. The same machinery end to end:
tests/cross_checks/engines/test_external.py (engine files), tests/cross_checks/sweep/test_lifecycle.py."""
import multiprocessing
import os
import signal
import time

import pytest

from cross_checks.core import processes


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:   # a zombie is not alive
        return open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="Linux /proc")
def test_a_command_s_stray_in_a_session_of_its_own_is_killed_and_its_output_tail_kept(tmp_path):
    script = ("setsid sleep 300 & echo $! > stray.pid; "
              "i=0; while [ $i -lt 2000 ]; do echo 'line of output'; i=$((i+1)); done; echo last words >&2")
    rc, timed_out, words = processes.run_command(["sh", "-c", script], tmp_path, 60.0)
    assert (rc, timed_out, words) == (0, False, "last words")   # stderr's tail is the message
    stray = int((tmp_path / "stray.pid").read_text())
    assert not _alive(stray)


def test_a_command_over_its_time_limit_is_killed_and_said_to_have_timed_out(tmp_path):
    rc, timed_out, words = processes.run_command(["sleep", "300"], tmp_path, 0.5)
    assert timed_out and rc != 0 and words == ""
    assert processes.exit_words(rc) == "was killed by signal SIGKILL"


def test_the_output_tail_is_bounded_however_much_the_command_prints(tmp_path):
    rc, _, words = processes.run_command(["sh", "-c", "yes 0123456789 2>/dev/null | head -c 3000000"],
                                         tmp_path, 60.0)
    assert rc == 0 and len(words) <= processes.OUTPUT_TAIL_CHARS + 1 and words.startswith("…")


def test_a_program_that_cannot_start_is_said_as_popen_says_it(tmp_path):
    with pytest.raises(processes.CannotStart, match=r"^cannot start './no-such-program': No such file"):
        processes.run_command(["./no-such-program"], tmp_path, 5.0)
    (tmp_path / "script").write_text("#!/bin/sh\n")
    with pytest.raises(processes.CannotStart, match=r"^cannot start './script': Permission denied"):
        processes.run_command(["./script"], tmp_path, 5.0)


def test_exit_words_name_the_signal_or_the_status():
    assert processes.exit_words(0) == "exited with status 0"
    assert processes.exit_words(3) == "exited with status 3"
    assert processes.exit_words(-signal.SIGTERM) == "was killed by signal SIGTERM"
    assert processes.exit_words(-(signal.SIGRTMIN + 3)) == f"was killed by signal {signal.SIGRTMIN + 3}"


def _ignore_sigterm_and_wait(ready):
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    ready.set()
    time.sleep(300)


def test_end_processes_kills_one_that_ignores_sigterm():
    ctx = multiprocessing.get_context("fork")
    ready = ctx.Event()
    stubborn = ctx.Process(target=_ignore_sigterm_and_wait, args=(ready,))
    plain = ctx.Process(target=time.sleep, args=(300,))
    stubborn.start()
    plain.start()
    assert ready.wait(60)
    processes.end_processes([stubborn, plain], grace_s=0.5)
    assert not stubborn.is_alive() and not plain.is_alive()
    assert (stubborn.exitcode, plain.exitcode) == (-signal.SIGKILL, -signal.SIGTERM)


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="Linux /proc")
def test_a_process_is_gone_when_its_id_is_free_or_taken_by_a_later_one():
    me, start = os.getpid(), processes.start_ticks(os.getpid())
    assert start > 0 and not processes.is_gone(me, start)
    assert processes.is_gone(me, start + 1)          # the id now belongs to a process started later
    ctx = multiprocessing.get_context("fork")
    child = ctx.Process(target=time.sleep, args=(0,))
    child.start()
    child.join()
    assert processes.is_gone(child.pid, 12345)


def test_with_timer_calls_on_time_once_while_the_work_outlasts_it_and_never_after_it_returns():
    """The one timer pattern (a process wait without pidfd, the reference's compile notice): ``on_time`` runs
    while ``work`` is still going (here it is what ends the work), and a work that returns first cancels it;
    a work that raises cancels it too."""
    import threading
    done = threading.Event()
    calls = []

    def on_time():
        calls.append(1)
        done.set()
    assert processes.with_timer(done.wait, 0.01, on_time) is True and calls == [1]
    assert processes.with_timer(lambda: None, 3600.0, on_time) is False and calls == [1]

    def boom():
        raise KeyError("work failed")
    with pytest.raises(KeyError):
        processes.with_timer(boom, 3600.0, on_time)
    timers = [t for t in threading.enumerate() if isinstance(t, threading.Timer)]
    for t in timers:     # a cancelled timer's thread ends at once; an uncancelled one would wait an hour
        t.join(30.0)
    assert not any(t.is_alive() for t in timers) and calls == [1]

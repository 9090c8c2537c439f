"""Process supervision, for every process rbcheck starts or stops: a command run under a time limit and a
supervisor (an engine file's simulator: :func:`run_command`), its output pipes read without hanging, its
whole process tree killed when it ends (its group, and what it started in sessions of its own), SIGTERM and
Ctrl-C while it runs; pool workers that die with the process that started them (:func:`die_with_parent`) and
are stopped by their ids (:func:`kill_pool`); and whether a process that left a name behind is gone
(:func:`is_gone`: a stale staging folder's owner).

Linux: /proc and prctl; elsewhere the same calls do what the platform allows (no supervisor, no subreaper).
What the signals themselves do to rbcheck (SIGTERM as Ctrl-C, one clean-up, the exit codes) is
:mod:`cross_checks.sweep.lifecycle`'s; how they reach the commands and workers is here.
"""
from __future__ import annotations

import contextlib
import ctypes
import os
import select
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

__all__ = ["CannotStart", "run_command", "supervised", "wait", "with_timer", "kill_group", "kill_strays",
           "TermKillsGroup", "Tail", "become_subreaper", "die_with_parent", "children", "descendants",
           "start_ticks", "is_gone", "end_processes", "kill_pool", "exit_words", "SUPERVISOR",
           "OUTPUT_TAIL_CHARS", "OUTPUT_TAIL_BYTES"]

#: Characters of a command's stderr/stdout kept for its message (:meth:`Tail.words`).
OUTPUT_TAIL_CHARS = 600
#: Bytes of each of the command's output streams kept while it runs (the rest is read and dropped: a
#: command that prints without end neither fills a disk nor holds memory).
OUTPUT_TAIL_BYTES = 4 * OUTPUT_TAIL_CHARS
PR_SET_PDEATHSIG, PR_SET_CHILD_SUBREAPER = 1, 36


class CannotStart(RuntimeError):
    """A command's program could not be started (no such file, not executable); ``str()`` says which and
    why, as Popen would."""


def _prctl(option: int, value: int) -> int | None:
    """Linux ``prctl(option, value)``'s result (0: done), None where there is no prctl."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(option, value, 0, 0, 0)
    except (OSError, AttributeError):
        return None


# --- what runs: /proc --------------------------------------------------------------------------------

def children(pid: int) -> set:
    """The direct children of ``pid`` (Linux /proc; empty elsewhere)."""
    out: set[int] = set()
    try:
        for task in os.listdir(f"/proc/{pid}/task"):
            with contextlib.suppress(OSError, ValueError):
                out.update(int(c) for c in Path(f"/proc/{pid}/task/{task}/children").read_text().split())
    except OSError:
        pass
    return out


def descendants(pid: int) -> set:
    seen, todo = set(), [pid]
    while todo:
        for c in children(todo.pop()):
            if c not in seen:
                seen.add(c)
                todo.append(c)
    return seen


def start_ticks(pid: int) -> int:
    """Start time of process ``pid`` in clock ticks since boot (Linux /proc); 0 when unknown."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        return int(stat.rsplit(")", 1)[1].split()[19])
    except (OSError, ValueError, IndexError):
        return 0


def is_gone(pid: int, start: int) -> bool:
    """True when the process ``pid`` that started at ``start`` (:func:`start_ticks`; 0: unknown) is no
    longer running: no process has that id, or another one (started at another time) has it now. Another
    user's process of that id counts as running."""
    if pid == os.getpid() and start == start_ticks(pid):
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        pass  # alive, another user's
    return start != 0 and start_ticks(pid) not in (0, start)  # the pid was reused by another process


# --- stopping processes ------------------------------------------------------------------------------

def end_processes(procs, grace_s: float = 2.0, terminate_first: bool = True) -> None:
    """Stop ``procs`` (multiprocessing processes): SIGTERM to each one alive, then, for each, ``grace_s`` to
    end before SIGKILL (which cannot be ignored, e.g. by a worker stuck in uninterruptible I/O) and
    ``grace_s`` more to be reaped; with ``terminate_first`` False, SIGKILL at once."""
    if terminate_first:
        for p in procs:
            if p.is_alive():
                p.terminate()
    for p in procs:
        if terminate_first:
            p.join(timeout=grace_s)
            if not p.is_alive():
                continue
        p.kill()
        p.join(timeout=grace_s)


def kill_pool(pool) -> None:
    """Stop a ``concurrent.futures.ProcessPoolExecutor``'s workers (they ignore SIGINT) by their own process
    ids, and make sure that its manager thread ends, which Python joins at exit. A worker killed while it
    wrote a large pickled result leaves part of the message in the result pipe; the manager thread then
    waits in ``os.read`` for the rest, for ever, because this process holds the pipe's write end too:
    closing that end once no worker is left turns the wait into end-of-file (a broken pool, which ends the
    thread) instead of a hang."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    # read before shutdown(), which drops them
    queue, manager = getattr(pool, "_result_queue", None), getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    end_processes(procs)
    if queue is not None and not any(p.is_alive() for p in procs):
        with contextlib.suppress(OSError):
            queue._writer.close()
    if manager is not None and manager is not threading.current_thread():
        manager.join(timeout=5)


def become_subreaper() -> bool:
    """Make this process the reaper of its orphaned descendants (Linux ``PR_SET_CHILD_SUBREAPER``): a
    child the command starts in a new session (``setsid cmd &``) is then still ours to find and kill."""
    return _prctl(PR_SET_CHILD_SUBREAPER, 1) == 0


def die_with_parent(parent_pid: int, signum: int = signal.SIGKILL) -> None:
    """This process gets ``signum`` when the thread that started it dies, however it dies (Linux
    ``PR_SET_PDEATHSIG``; nothing elsewhere); it exits at once if ``parent_pid`` died before that took
    effect."""
    if not sys.platform.startswith("linux") or _prctl(PR_SET_PDEATHSIG, int(signum)) is None:
        return
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)


def kill_group(proc) -> None:
    """SIGKILL the process group of ``proc`` (a Popen started in a session of its own: the command and
    anything it started), then reap it."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    proc.wait()


#: The commands running now in this process (other threads' runs), never taken for a run's strays.
_LIVE: set = set()
_LIVE_LOCK = threading.Lock()


def kill_strays(before: set) -> None:
    """SIGKILL and reap every descendant of this process that was not there before the command started:
    what the command left running, in its group or in a session of its own (reparented to us) — but
    not a command another thread runs now, nor what it started."""
    me = os.getpid()
    for _ in range(3):   # a dying process may have started another in the meantime
        with _LIVE_LOCK:
            others = set(_LIVE)
        busy = others | {d for pid in others for d in descendants(pid)}
        strays = descendants(me) - before - busy
        if not strays:
            return
        for pid in strays:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signal.SIGKILL)
        for pid in strays:
            with contextlib.suppress(ChildProcessError, OSError):
                os.waitpid(pid, 0)   # ours once reparented (subreaper); others are reaped by their parent


# --- running a command ---------------------------------------------------------------------------

class TermKillsGroup:
    """While a command runs in the main thread: SIGTERM (a sweep stopping its workers) first kills the
    command's process group and removes the run's private directory ``private`` (a worker dies of that
    SIGTERM at once: no ``finally`` of the run would remove it), so neither outlives the worker."""

    def __init__(self, proc, private: Path | None = None):
        self.proc, self.prev, self.private = proc, None, private

    def __enter__(self):
        if (threading.current_thread() is threading.main_thread()
                and signal.getsignal(signal.SIGTERM) == signal.SIG_DFL):
            def on_term(signum, frame):
                kill_group(self.proc)
                if self.private is not None:
                    shutil.rmtree(self.private, ignore_errors=True)
                signal.signal(signal.SIGTERM, signal.SIG_DFL)
                os.kill(os.getpid(), signal.SIGTERM)
            self.prev = signal.signal(signal.SIGTERM, on_term)
        return self

    def __exit__(self, *exc):
        if self.prev is not None:
            signal.signal(signal.SIGTERM, self.prev)
        return False


class Tail(threading.Thread):
    """Reads one of the command's output pipes to its end, keeping only the last OUTPUT_TAIL_BYTES."""

    def __init__(self, pipe):
        super().__init__(daemon=True)
        self.pipe, self.kept = pipe, b""

    def run(self):
        try:
            for chunk in iter(lambda: self.pipe.read1(65536), b""):
                self.kept = (self.kept + chunk)[-OUTPUT_TAIL_BYTES:]
        except (OSError, ValueError):
            pass

    def words(self) -> str:
        text = self.kept.decode("utf-8", errors="replace")
        lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
        text = " | ".join(lines)
        return text if len(text) <= OUTPUT_TAIL_CHARS else "…" + text[-OUTPUT_TAIL_CHARS:]


#: The command's supervisor (``python -I -S -c``, argv: rbcheck's pid, the run's private directory or "",
#: then the command): it starts the command as its child in the session ``run_command`` made, and passes its
#: exit status on (a signal's death as that signal). It dies with rbcheck's process that started it, whatever
#: ended that one (``kill -9`` of the group, ``timeout -s KILL``, a CI cancel, the OOM killer): Linux sends it
#: SIGTERM then (``PR_SET_PDEATHSIG``), and it kills the command and everything the command started (it is
#: their subreaper) and removes the run's private directory before going. Only the supervisor can get that
#: signal: a parent-death signal is not inherited by the command's own children.
SUPERVISOR = r"""
import ctypes, os, shutil, signal, sys
parent, private, argv = int(sys.argv[1]), sys.argv[2], sys.argv[3:]
libc = ctypes.CDLL(None, use_errno=True)
def descendants():
    out, todo = [], [os.getpid()]
    while todo:
        p = todo.pop()
        try:
            tasks = os.listdir(f"/proc/{p}/task")
        except OSError:
            continue
        for t in tasks:
            try:
                with open(f"/proc/{p}/task/{t}/children") as fh:
                    kids = [int(c) for c in fh.read().split()]
            except (OSError, ValueError):
                kids = []
            out += kids
            todo += kids
    return out
def die(signum, frame):
    for _ in range(3):
        for pid in descendants():
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
    if private:   # the run's private directory, which rbcheck can no longer remove
        shutil.rmtree(private, ignore_errors=True)
    os._exit(128 + signum)
signal.signal(signal.SIGTERM, die)
libc.prctl(36, 1, 0, 0, 0)                    # PR_SET_CHILD_SUBREAPER
libc.prctl(1, int(signal.SIGTERM), 0, 0, 0)   # PR_SET_PDEATHSIG
if os.getppid() != parent:                    # rbcheck died before prctl took effect
    die(signal.SIGTERM, None)
pid = os.fork()
if pid == 0:
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        os.execvp(argv[0], argv)
    except OSError as exc:
        sys.stderr.write(f"cannot start {argv[0]!r}: {exc.strerror}\n")
        sys.stderr.flush()
    os._exit(127)
while True:
    try:
        _, status = os.waitpid(pid, 0)
        break
    except InterruptedError:
        continue
if os.WIFSIGNALED(status):
    import resource
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    signal.signal(os.WTERMSIG(status), signal.SIG_DFL)
    os.kill(os.getpid(), os.WTERMSIG(status))
os._exit(os.waitstatus_to_exitcode(status))
"""


def supervised(argv: list, cwd: Path, private: Path | None = None) -> list:
    """``argv`` under :data:`SUPERVISOR` (Linux; elsewhere ``argv`` itself). :class:`CannotStart`, as Popen
    would raise it, when its program cannot be started: the supervisor's child would only say so in its
    status."""
    program = argv[0] if os.sep in argv[0] else shutil.which(argv[0])
    if program is not None and os.sep in argv[0] and not os.path.isabs(program):
        program = os.path.join(cwd, program)
    if program is None or not os.path.isfile(program):
        raise CannotStart(f"cannot start {argv[0]!r}: {os.strerror(2)}")
    if not os.access(program, os.X_OK):
        raise CannotStart(f"cannot start {argv[0]!r}: {os.strerror(13)}")
    if not os.path.isdir(f"/proc/{os.getpid()}"):
        return argv
    return [sys.executable, "-I", "-S", "-c", SUPERVISOR, str(os.getpid()), str(private or ""), *argv]


def run_command(argv: list, cwd: Path, timeout_s: float, private: Path | None = None):
    """Run ``argv`` in ``cwd`` in a new process group under a time limit, under a supervisor that ends it if
    this process dies (:data:`SUPERVISOR`).

    Returns ``(returncode, timed_out, output_tail)``; raises :class:`CannotStart` when it cannot be started.
    The wait is a pidfd poll or ``waitpid`` (no polling latency); at the end the command's whole process
    tree is killed, and whatever it left running (:func:`kill_strays`). Its output is read as it comes, only
    the tail kept (:class:`Tail`: a command that prints without end holds neither memory nor the wait). A
    Ctrl-C meanwhile kills the command's tree too before it propagates. ``private``, the run's private
    directory, is removed if SIGTERM ends this process meanwhile (:class:`TermKillsGroup`), or by the
    supervisor if this process dies.
    """
    become_subreaper()
    before = descendants(os.getpid())
    try:
        proc = subprocess.Popen(supervised(argv, cwd, private), cwd=cwd, stdin=subprocess.DEVNULL,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    except OSError as exc:
        raise CannotStart(f"cannot start {argv[0]!r}: {exc.strerror or exc}") from None
    with _LIVE_LOCK:
        _LIVE.add(proc.pid)
    out, err = Tail(proc.stdout), Tail(proc.stderr)
    out.start()
    err.start()
    try:
        with TermKillsGroup(proc, private):
            timed_out = wait(proc, timeout_s)
    finally:
        kill_group(proc)  # on time-out, Ctrl-C, or stray children of a finished command
        with _LIVE_LOCK:
            _LIVE.discard(proc.pid)
        kill_strays(before)
        for t in (out, err):
            t.join(timeout=5.0)
        for pipe in (proc.stdout, proc.stderr):
            with contextlib.suppress(OSError):
                if pipe is not None:
                    pipe.close()
    return proc.returncode, timed_out, err.words() or out.words()


def with_timer(work, after_s: float, on_time) -> bool:
    """Call ``work()``; when it has not returned after ``after_s`` seconds, ``on_time()`` runs once, from a
    daemon timer thread, while it goes on (it may end it: kill the process ``work`` waits for). True when
    ``on_time`` ran. The timer is cancelled however ``work`` ends."""
    fired = threading.Event()

    def fire():
        fired.set()
        on_time()

    timer = threading.Timer(after_s, fire)
    timer.daemon = True
    timer.start()
    try:
        work()
    finally:
        timer.cancel()
    return fired.is_set()


def wait(proc, timeout_s: float) -> bool:
    """Wait for ``proc`` at most ``timeout_s``; True when the time ran out. A pidfd (Linux) wakes the
    instant the process exits; elsewhere a timer thread kills the group at the limit."""
    try:
        fd = os.pidfd_open(proc.pid)
    except (AttributeError, OSError):
        def kill():
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGKILL)
        return with_timer(proc.wait, timeout_s, kill)
    try:
        poller = select.poll()
        poller.register(fd, select.POLLIN)
        deadline = time.monotonic() + timeout_s
        while not poller.poll(max(0.0, deadline - time.monotonic()) * 1000.0):
            if time.monotonic() >= deadline:
                return True
        return False
    finally:
        os.close(fd)



def exit_words(rc: int) -> str:
    """How a process of Popen's return code ``rc`` ended: "exited with status 3", "was killed by signal
    SIGKILL"."""
    if rc >= 0:
        return f"exited with status {rc}"
    try:
        return f"was killed by signal {signal.Signals(-rc).name}"
    except ValueError:  # e.g. a real-time signal, which has no name
        return f"was killed by signal {-rc}"


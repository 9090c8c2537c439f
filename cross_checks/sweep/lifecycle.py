"""How rbcheck's processes end: SIGTERM is handled like Ctrl-C (the same clean-up runs: staging
directories removed, workers stopped, exit 143 instead of 130), and worker processes die with the
process that started them, even when it is killed with SIGKILL (Linux PR_SET_PDEATHSIG); the time limits
of a run. Starting, supervising and stopping the processes themselves: :mod:`cross_checks.core.processes`."""
from __future__ import annotations

import _thread
import contextlib
import os
import signal
import sys
import threading
import time

from cross_checks.core import processes

__all__ = ["Terminated", "handle_sigterm", "interrupted_by", "signals_deferred",
           "interrupted_exception", "await_group_signal", "exit_at_once", "worker_init", "EXIT_TERMINATED",
           "TimeLimitExceeded", "time_limit", "each_within_limits"]

#: 128 + SIGTERM, what a shell reports for a process ended by SIGTERM.
EXIT_TERMINATED = 128 + signal.SIGTERM


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived; a KeyboardInterrupt so that every Ctrl-C clean-up path runs for it too."""


#: The signal that interrupted this process (0: none yet). Only the first one raises: the clean-up it
#: starts (workers stopped, staging and private run directories removed, the one line said) must run to
#: its end, and ``timeout`` forwarding Ctrl-C to the process group, or a user pressing Ctrl-C twice,
#: sends a second one while it runs.
_interrupted = [0]


#: The lists of :func:`signals_deferred` blocks running now: a signal is recorded in each, not raised.
_deferring: list = []


def _on_signal(signum, frame):
    if _deferring:   # a clean-up, a fork hook: recorded, acted on at the block's end
        if not _interrupted[0]:
            _interrupted[0] = signum
        for pending in _deferring:
            pending.append(signum)
        return
    if _interrupted[0]:
        return   # cleaning up after the first one: the exit code stays the first one's
    _interrupted[0] = signum
    raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


@contextlib.contextmanager
def signals_deferred():
    """A block no Ctrl-C or SIGTERM interrupts (a clean-up that must finish: workers stopped, the staging
    folder removed); the signals that came meanwhile are in the list it yields, for the caller to act on
    after it (the first one is also :func:`interrupted_by`)."""
    pending: list = []
    _deferring.append(pending)
    try:
        yield pending
    finally:
        _deferring.remove(pending)


#: How long a sweep whose workers died waits for a signal to reach it too: a SIGTERM sent to the process
#: group (``timeout``, ``kill -TERM -PGID``) kills the workers (SIGTERM at its default there) and is handled
#: here only when this process is next scheduled; on 2 loaded cores that took longer than the clean-up.
GROUP_SIGNAL_GRACE_S = 1.0


def await_group_signal(pending: list, grace_s: float = GROUP_SIGNAL_GRACE_S) -> None:
    """Inside :func:`signals_deferred` (``pending`` its list): wait at most ``grace_s`` for a signal."""
    deadline = time.monotonic() + grace_s
    while not pending and time.monotonic() < deadline:
        time.sleep(0.01)


def interrupted_exception(signum: int) -> KeyboardInterrupt:
    """What a signal raises: Terminated for SIGTERM, KeyboardInterrupt for Ctrl-C."""
    return Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def _on_sigterm(signum, frame):
    _on_signal(signal.SIGTERM, frame)


def interrupted_by() -> int:
    """The signal (SIGINT or SIGTERM) that interrupted this process since :func:`handle_sigterm`, or 0."""
    return _interrupted[0]


def _redeliver_swallowed_sigterm(unraisable, _previous=None) -> None:
    """``sys.unraisablehook``: a SIGTERM or Ctrl-C whose exception was raised inside a ``__del__`` or a
    weakref callback (where Python prints "Exception ignored" and carries on) is sent again, so that it
    lands in the main flow instead of being lost; anything else goes to the previous hook. It is sent from
    a bare thread 10 ms later: ``os.kill`` here, or anything that waits here (``Thread.start``), would run
    the handler at once, inside the hook."""
    if isinstance(unraisable.exc_value, KeyboardInterrupt) and _interrupted[0]:
        signum, _interrupted[0] = _interrupted[0], 0   # lost: the re-sent one raises again
        _thread.start_new_thread(_send_signal_later, (0.01, signum))
        return
    (_previous or sys.__unraisablehook__)(unraisable)


def _send_signal_later(delay_s: float, signum: int = signal.SIGTERM) -> None:
    time.sleep(delay_s)
    os.kill(os.getpid(), signum)


_fork_mask = threading.local()


def _block_before_fork() -> None:
    _fork_mask.before = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})


def _unblock_in_parent() -> None:
    """A signal that came during the fork is delivered when the mask is restored, here, inside the fork's
    hook, where an exception is swallowed: it is recorded instead and handed to the main thread again
    (``_thread.interrupt_main``), whose next Python line after ``os.fork`` then raises it."""
    with signals_deferred() as pending:
        signal.pthread_sigmask(signal.SIG_SETMASK, getattr(_fork_mask, "before", set()))
    if pending and _interrupted[0] == pending[0]:
        _interrupted[0] = 0
        _thread.interrupt_main(pending[0])


def _unblock_in_child() -> None:
    """A forked child (a pool worker) gets a worker's handlers before it can take a signal: with the parent's,
    a Ctrl-C or SIGTERM sent to the group while it starts raised inside multiprocessing's start-up and
    printed a traceback. One blocked meanwhile is delivered now, to these handlers."""
    with contextlib.suppress(ValueError, OSError):
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_SETMASK, getattr(_fork_mask, "before", set()))


_fork_hooks: list = []
_exit_hook: list = []


#: The exit code :func:`exit_at_once` asked for (None: the interpreter's usual exit).
_exit_code: list = [None]


def _exit_now_if_asked() -> None:
    if _exit_code[0] is None:
        return
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(_exit_code[0])


def exit_at_once(code: int) -> None:
    """After an interrupt whose clean-up is done and said: end the process with ``code`` as soon as Python's
    exit reaches the atexit handlers (registered first, they run last), skipping the rest of the interpreter's
    finalisation, where a C extension interrupted in its initialisation, or a library's thread, could
    still hang or abort the exit. A worker process still alive (a pool the signal interrupted while it
    forked its workers) is killed now: multiprocessing's own atexit handler would wait for it for ever."""
    _exit_code[0] = code
    mp = sys.modules.get("multiprocessing")
    if mp is None:
        return
    for p in mp.active_children():
        with contextlib.suppress(Exception):
            processes.end_processes([p], terminate_first=False)


def handle_sigterm() -> None:
    """Make SIGTERM raise Terminated and Ctrl-C KeyboardInterrupt in the main thread (no-op elsewhere),
    the first of them only (:data:`_interrupted`), also when it arrives while Python runs a finaliser or
    weakref callback (see :func:`_redeliver_swallowed_sigterm`)."""
    _interrupted[0] = 0
    if not _exit_hook:
        import atexit
        atexit.register(_exit_now_if_asked)
        _exit_hook.append(True)
    try:
        signal.signal(signal.SIGTERM, _on_sigterm)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:   # not when the caller ignores it
            signal.signal(signal.SIGINT, _on_signal)
    except ValueError:  # not the main thread
        return
    if not _fork_hooks and hasattr(os, "register_at_fork"):
        os.register_at_fork(before=_block_before_fork, after_in_parent=_unblock_in_parent,
                            after_in_child=_unblock_in_child)
        _fork_hooks.append(True)
    previous = sys.unraisablehook
    if getattr(previous, "__name__", "") != "_hook":
        def _hook(unraisable):
            _redeliver_swallowed_sigterm(unraisable, previous)
        sys.unraisablehook = _hook


def worker_init(parent_pid: int | None = None) -> None:
    """Initializer of rbcheck's pool workers: Ctrl-C and SIGTERM are the parent's to handle (it then
    stops the workers by their ids); a worker must not print its own traceback, and it is killed
    when its parent dies without stopping it (kill -9)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    processes.die_with_parent(parent_pid if parent_pid is not None else os.getppid())


class TimeLimitExceeded(Exception):
    """Raised inside a reference solve or a run that took longer than its time limit."""


@contextlib.contextmanager
def time_limit(seconds: float | None, what: str):
    """Raise TimeLimitExceeded("<what> took longer than the time limit of N s") in the body after
    ``seconds`` of wall time. A SIGALRM timer: only in a process's main thread (pool workers and
    ``--jobs 1``); elsewhere (e.g. a Dask worker thread) the body runs without a limit."""
    if not seconds or threading.current_thread() is not threading.main_thread():
        yield
        return

    message = f"{what} took longer than the time limit of {seconds:g} s"
    fired = []

    def on_alarm(signum, frame):
        fired.append(True)
        raise TimeLimitExceeded(message)

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, float(seconds))
    try:
        yield
    except TimeLimitExceeded:
        raise
    except Exception as exc:
        # the alarm's exception raised inside C code may come out as another one (e.g. a NumPy TypeError):
        # once the alarm has fired, whatever ends the body is the time limit
        if fired:
            raise TimeLimitExceeded(message) from exc
        raise
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)


def each_within_limits(call, items: list, time_limit_s: float | None, what: str) -> list:
    """``call(items)`` (one result per item) within the items' time limits added up; when it fails as a
    whole (over that limit, an error of its own), ``call([item])`` for each item alone within its own
    limit, so that every failure is its own item's: a result per item, or the message of its failure (a
    time limit's naming cross_checks/core/tolerances.py, where the limits are set)."""
    try:
        with time_limit(time_limit_s and time_limit_s * len(items), what):
            return list(call(items))
    except Exception as exc:  # noqa: BLE001 - a failure is the item's result
        if len(items) > 1:
            return [r for it in items for r in each_within_limits(call, [it], time_limit_s, what)]
        if isinstance(exc, TimeLimitExceeded):
            return [f"{exc} (cross_checks/core/tolerances.py)"]
        return [f"{type(exc).__name__}: {exc}".strip()]

"""How rbcheck's processes end: SIGTERM is handled like Ctrl-C (the same clean-up runs: staging
directories removed, workers stopped, exit 143 instead of 130), and worker processes die with the
process that started them, even when it is killed with SIGKILL (Linux PR_SET_PDEATHSIG)."""
from __future__ import annotations

import _thread
import contextlib
import ctypes
import os
import signal
import sys
import threading
import time

__all__ = ["Terminated", "handle_sigterm", "worker_init", "EXIT_TERMINATED", "TimeLimitExceeded",
           "time_limit", "each_within_limits"]

#: 128 + SIGTERM, what a shell reports for a process ended by SIGTERM.
EXIT_TERMINATED = 128 + signal.SIGTERM
_PR_SET_PDEATHSIG = 1


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived; a KeyboardInterrupt so that every Ctrl-C clean-up path runs for it too."""


def _on_sigterm(signum, frame):
    raise Terminated()


def _redeliver_swallowed_sigterm(unraisable, _previous=None) -> None:
    """``sys.unraisablehook``: a SIGTERM whose Terminated was raised inside a ``__del__`` or a weakref
    callback (where Python prints "Exception ignored" and carries on) is sent again, so that it lands in
    the main flow instead of being lost; anything else goes to the previous hook. It is sent from a bare
    thread 10 ms later: ``os.kill`` here, or anything that waits here (``Thread.start``), would run the
    handler at once, inside the hook."""
    if isinstance(unraisable.exc_value, Terminated):
        _thread.start_new_thread(_send_sigterm_later, (0.01,))
        return
    (_previous or sys.__unraisablehook__)(unraisable)


def _send_sigterm_later(delay_s: float) -> None:
    time.sleep(delay_s)
    os.kill(os.getpid(), signal.SIGTERM)


def handle_sigterm() -> None:
    """Make SIGTERM raise Terminated in the main thread (no-op elsewhere), also when it arrives while
    Python runs a finaliser or weakref callback (see :func:`_redeliver_swallowed_sigterm`)."""
    try:
        signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread
        return
    previous = sys.unraisablehook
    if getattr(previous, "__name__", "") != "_hook":
        def _hook(unraisable):
            _redeliver_swallowed_sigterm(unraisable, previous)
        sys.unraisablehook = _hook


def _die_with_parent(parent_pid: int) -> None:
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)


def worker_init(parent_pid: int | None = None) -> None:
    """Initializer of rbcheck's pool workers: Ctrl-C and SIGTERM are the parent's to handle (it then
    stops the workers by their ids); a worker must not print its own traceback, and it is killed
    when its parent dies without stopping it (kill -9)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _die_with_parent(parent_pid if parent_pid is not None else os.getppid())


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

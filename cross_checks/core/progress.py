"""Progress of a long command that reaches the user in a terminal AND in a CI log.

In a terminal (stderr is a TTY) a tqdm bar on stderr; anywhere else (a CI log, a pipe, a file) one plain
line on STDOUT every ``LINE_INTERVAL_S`` seconds, flushed at once, plus a last line when the stage ends
(stderr stays the channel of errors: an error or an interruption is still one line there)::

    rbcheck sweep: runs 120/455 (26%) in 14 s, ~40 s left; last: tennis_racket mujoco:rk4

Every stage of ``rbcheck sweep`` (the references, the runs, the results files, the report) goes through
:func:`stage` (one line: a stage starts) and :class:`Progress` (a counted stage), so a log shows no
silent stretch longer than the interval. ``enabled=False`` prints nothing (library calls: tests, the
pytest plugin).
"""
from __future__ import annotations

import contextlib
import re
import sys
import time

__all__ = ["LINE_INTERVAL_S", "Progress", "stage", "is_tty", "say", "degrade_unencodable", "shown",
           "EscapingStream", "escaped_output"]

#: Seconds between two progress lines without a terminal: often enough that a CI log never looks hung
#: (GitHub Actions streams lines as they come), rarely enough that a 1000-run sweep prints ~20 lines.
LINE_INTERVAL_S = 5.0


_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f]")


def shown(text) -> str:
    """``text`` with every control character but newline and tab written as ``\\xNN`` (ESC as ``\\x1b``, CR as
    ``\\x0d``): text from an engine file, a command's stderr or a results directory someone sent can then
    neither move the cursor, rewrite a CI log's lines nor forge one (an "OK: no regression" of its own)."""
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", str(text))


class EscapingStream:
    """A text stream that writes through :func:`shown`; everything else is the wrapped stream's. The progress
    bar (tqdm: carriage returns on purpose) writes to ``raw``."""

    def __init__(self, stream):
        self.raw = stream

    def write(self, text):
        return self.raw.write(shown(text))

    def __getattr__(self, name):
        return getattr(self.raw, name)


@contextlib.contextmanager
def escaped_output():
    """sys.stdout and sys.stderr through :class:`EscapingStream` for the block (restored after)."""
    out, err = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = EscapingStream(out), EscapingStream(err)
    try:
        yield
    finally:
        sys.stdout, sys.stderr = out, err


def is_tty(stream) -> bool:
    """Whether ``stream`` is a terminal (False for a closed or stream-less object)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def say(text: str, stream=None) -> None:
    """Print a line and flush it; a reader that went away (``rbcheck sweep | head -1``: a closed pipe) never
    stops the work: the stream is pointed at /dev/null and the command goes on writing its results."""
    stream = sys.stdout if stream is None else stream
    try:
        print(text, file=stream, flush=True)
    except (BrokenPipeError, ValueError):   # (ValueError: the stream was closed)
        _discard(stream)
    except OSError as exc:
        if exc.errno in (32, 9):   # EPIPE, EBADF: nobody reads any more
            _discard(stream)
        else:
            raise


def _discard(stream) -> None:
    """From now on, what goes to ``stream`` goes nowhere (and Python's flush at exit does not fail)."""
    import os
    try:
        fd = stream.fileno()
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, fd)
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass


#: How characters a stream cannot encode (PYTHONIOENCODING=ascii, a C locale) are written instead.
_ASCII = {"Δ": "d", "δ": "delta", "ω": "w", "χ": "chi", "θ": "theta", "τ": "tau", "—": "-", "–": "-",
          "−": "-", "…": "...", "×": "x", "≤": "<=", "≥": ">=", "≈": "~", "±": "+/-", "²": "^2", "³": "^3",
          "⁻": "^-", "¹": "1", "ᵖ": "^p", "⁺": "+", "→": "->", "·": "*", "√": "sqrt", "✓": "v", "✗": "x",
          "†": "+", "π": "pi", "µ": "u", "μ": "u", "’": "'", "‘": "'", "“": '"', "”": '"', "⟂": "_|_",
          "▼": "v", "≪": "<<", "≫": ">>"}


def _degrade(exc):
    import unicodedata
    out = []
    for ch in exc.object[exc.start:exc.end]:
        rep = _ASCII.get(ch)
        if rep is None:
            rep = unicodedata.normalize("NFKD", ch).encode("ascii", "ignore").decode("ascii") or "?"
        out.append(rep)
    return "".join(out), exc.end


def degrade_unencodable(*streams) -> None:
    """Make ``streams`` write what their encoding cannot hold as ASCII look-alikes (Δt -> dt, ω -> w,
    — -> -) instead of failing: rbcheck's words are full of Greek letters and dashes, and a CI runner's
    locale may be ASCII."""
    import codecs
    try:
        codecs.lookup_error("rbcheck-ascii")
    except LookupError:
        codecs.register_error("rbcheck-ascii", _degrade)
    for stream in streams:
        enc = getattr(stream, "encoding", None)
        if not enc or not hasattr(stream, "reconfigure"):
            continue
        try:
            "Δω—…×≤".encode(enc)
        except (UnicodeEncodeError, LookupError):
            try:
                stream.reconfigure(errors="rbcheck-ascii")
            except (ValueError, OSError):
                pass


def _seconds(s: float) -> str:
    return f"{s:.0f} s" if s < 120 else f"{s / 60:.1f} min"


def stage(prefix: str, message: str, *, enabled: bool = True, stream=None) -> None:
    """One line ``"<prefix>: <message>"`` on stdout (or ``stream``), flushed: a stage begins."""
    if enabled:
        say(f"{prefix}: {message}", stream)


class Progress:
    """Counted progress of one stage (a context manager): ``update(n=1, last="what just finished")``;
    with ``total_work``, ``update(..., work=w)`` says how much of it each item was (the time left then
    follows the work, not the count).

    ``prefix`` names the command (``rbcheck sweep``), ``what`` the items (``runs``). ``enabled``:
    print anything at all; ``tty``: force the bar (True) or the lines (False), default: whether stderr
    (or the given ``stream``) is a terminal. ``interval_s`` and ``clock`` exist for the tests.
    """

    def __init__(self, prefix: str, what: str, total: int, *, enabled: bool = True, stream=None,
                 tty: bool | None = None, interval_s: float = LINE_INTERVAL_S, clock=time.monotonic,
                 total_work: float | None = None):
        self.prefix, self.what, self.total, self.enabled = prefix, what, int(total), enabled
        # items of unequal size (a sweep's runs, longest first): the time left is estimated from the
        # work done (``update(work=...)``), not from the count
        self.total_work, self.work_done = total_work, 0.0
        bar = is_tty(sys.stderr if stream is None else stream) if tty is None else tty
        self.stream = stream if stream is not None else (sys.stderr if bar else sys.stdout)
        self.interval_s, self.clock = interval_s, clock
        self.done, self.last = 0, ""
        self.t0 = self._last_line = clock()
        self._samples: list = []   # (elapsed s, items done, work done) at each update: the time-left fit
        self.bar = None
        if enabled and bar:
            from tqdm import tqdm
            self.bar = tqdm(total=self.total, unit=what.rstrip("s") or what, desc=f"{prefix}: {what}",
                            file=getattr(self.stream, "raw", self.stream), dynamic_ncols=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close(finished=exc[0] is None)
        return False

    def update(self, n: int = 1, last: str = "", work: float = 0.0) -> None:
        self.done += n
        self.work_done += work
        self.last = last or self.last
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.update(n)
            if last:
                self.bar.set_postfix_str(last, refresh=False)
            return
        now = self.clock()
        if n:
            self._samples.append((now - self.t0, self.done, self.work_done))
        if now - self._last_line >= self.interval_s and self.done < self.total:
            self._last_line = now
            self._line(now)

    def _line(self, now: float, final: str = "") -> None:
        """A progress line; ``final`` ("done") ends the stage's lines."""
        elapsed = now - self.t0
        pct = f" ({100 * self.done / self.total:.0f}%)" if self.total else ""
        tail = f", {final}" if final else ""
        left = self._time_left(elapsed) if not final and 0 < self.done < self.total else None
        if left is not None:
            tail = f", ~{_seconds(left)} left"
        if self.last and not final:
            tail += f"; last: {self.last}"
        say(f"{self.prefix}: {self.what} {self.done}/{self.total}{pct} in {_seconds(elapsed)}{tail}",
            self.stream)

    def _time_left(self, elapsed: float) -> float | None:
        """Seconds left: the times at which items finished fitted as ``start + a × items + b × work``
        (non-negative least squares), carried over what remains.

        A cost per item (a process, a reference, the metrics of a run) beside the cost per unit of work
        (steps) keeps a sweep's many short runs after its long ones from reading "~0 s left"; the start
        term keeps a slow first item (imports, a font cache) from being multiplied by every item left.
        Until there are more finishing times than terms: proportional to the work done, or, for a count
        alone, None (no estimate: the first items' times hold the start-up, which would be multiplied by
        every item left: "~7.2 min left" after the report's first figure, done 6 s later)."""
        total_work = self.total_work or 0.0
        work = total_work > 0 and self.work_done > 0
        rest_n = self.total - self.done
        rest_w = max(total_work - self.work_done, 0.0) if work else 0.0
        pts = self._samples
        if len({p[1] for p in pts}) > 2 + work:
            import numpy as np
            from scipy.optimize import nnls
            a = np.array([(1.0, n, w) if work else (1.0, n) for _, n, w in pts])
            b = np.array([t for t, _, _ in pts])
            scale = np.maximum(np.abs(a).max(axis=0), 1e-300)   # columns of comparable size for nnls
            coef = nnls(a / scale, b)[0] / scale
            return float(coef[1] * rest_n + (coef[2] * rest_w if work else 0.0))
        if work:
            return elapsed * rest_w / self.work_done
        return None

    def close(self, finished: bool = True) -> None:
        """End the stage: the bar closes; without a terminal a last line says it is done. A stage
        stopped by an error or Ctrl-C prints nothing more: the command's own one-line message says why."""
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.close()
            self.bar = None
            return
        if self._last_line is not None and finished:
            self._line(self.clock(), "done")
        self._last_line = None

"""Engine files: any simulator, in any language, as an rbcheck engine (``--engine-file FILE``).

An engine file (TOML) names an engine and, per variant, its declared order, optional precision and the
command that runs one simulation; :func:`load_engine_file` validates it (EngineFileError,
``FILE: FIELD: REASON``) into an :class:`ExternalEngine`. A run writes the resolved scenario JSON, runs the
command with its placeholders (:data:`PLACEHOLDERS`) filled in a private temporary directory, kills its
whole process tree when it ends, and reads the trajectory CSV it wrote: EngineError (with the command's
own words) when it fails, a ``diverged`` Run when a row after t = 0 is non-finite or beyond BLOWUP_LIMIT.
The format, the placeholders, how a run goes and what fails it: docs/engines.md, "Engine files".

This module is the file and its protocol (the TOML, the JSON the command reads, the CSV it writes); how the
command runs (its supervisor, its time limit, its process tree killed, its output read without hanging, a
Ctrl-C or SIGTERM meanwhile) is :func:`cross_checks.core.processes.run_command`.
"""
from __future__ import annotations

import dataclasses
import hashlib
import math
import os
import shutil
import string
import tempfile
import tomllib
from pathlib import Path

import numpy as np

from cross_checks.core import processes
from cross_checks.core import tolerances as tol
from cross_checks.core.names import NAME_RE, unknown_key_reason
from cross_checks.engines.base import DEFAULT_TRAITS, EngineAdapter, EngineError, Variant
from reference_sim.simulate import Run, bad_rows, blowup_words, diverged

__all__ = ["EngineFileError", "ExternalEngine", "load_engine_file", "PLACEHOLDERS", "DEFAULT_TIMEOUT_S"]

PLACEHOLDERS = ("scenario_json", "dt", "steps", "duration", "out_csv", "engine_dir")
#: Time limit of one run when the engine file sets none: generous for any compiled engine on the
#: catalog (40 000 steps at 1 ms/step is 40 s), short enough that a hung command is noticed.
DEFAULT_TIMEOUT_S = 300.0
MAX_TIMEOUT_S = 86400.0
#: A trajectory row holds 14 numbers of ≤ 25 characters; 1 KiB per row leaves room for extra columns.
#: A larger CSV is garbage and is not read.
MAX_CSV_BYTES_PER_ROW = 1024
#: The folder fingerprint hashes the content of at most this many files (then their sizes and times), and
#: skips hidden folders, __pycache__ and rbcheck's own results directories.
FOLDER_MAX_FILES = 5000
FOLDER_CONTENT_MAX_BYTES = 64 * 2 ** 20

_TOP = {"name", "version", "description", "timeout", "variants", "body_forms"}
_VARIANT = {"order", "description", "command", "precision", "invariance_findings"}
_FINDING = {"transform", "within", "quantities", "reason"}


class EngineFileError(ValueError):
    """A bad engine file; ``str()`` is ``FILE: FIELD: REASON``."""

    def __init__(self, path, field_: str, reason: str):
        self.path, self.field, self.reason = str(path), field_, reason
        super().__init__(f"{path}: {field_}: {reason}" if field_ else f"{path}: {reason}")


# --- loading and validation -------------------------------------------------------------------------

def _check_keys(path, table: dict, allowed, where: str):
    for k in table:
        if k not in allowed:
            raise EngineFileError(path, f"{where}{k}", unknown_key_reason(k, allowed))


def _parse_argument(path, fld: str, arg) -> list:
    """``[(literal, placeholder or None), ...]`` of one command argument; EngineFileError when bad."""
    if not isinstance(arg, str):
        raise EngineFileError(path, fld, f"must be a string, got {arg!r}")
    try:
        parts = list(string.Formatter().parse(arg))
    except ValueError as exc:
        raise EngineFileError(path, fld, f"bad placeholder syntax in {arg!r}: {exc} (write {{{{ and }}}} for "
                                         "literal braces)") from None
    out = []
    for literal, name, spec, conv in parts:
        if name is not None:
            if name not in PLACEHOLDERS:
                raise EngineFileError(path, fld, f"unknown placeholder {{{name}}} in {arg!r}; placeholders: "
                                                 + ", ".join(f"{{{p}}}" for p in PLACEHOLDERS))
            if spec or conv:
                raise EngineFileError(path, fld, f"placeholder {{{name}}} takes no format spec or conversion "
                                                 f"(got {arg!r}); values are printed to full precision")
        out.append((literal, name))
    return out


def _resolve_program(path, folder: Path, fld: str, program: str) -> str:
    """The program to run: a path (relative to the engine file's folder) that must be an executable
    file, or a name found on PATH."""
    if not program:
        raise EngineFileError(path, fld, "is empty; name the program to run")
    if "/" in program:
        p = Path(program) if Path(program).is_absolute() else folder / program
        if not p.exists():
            raise EngineFileError(path, fld, f"{program}: no such file (looked in {folder}; build it first?)")
        if not p.is_file():
            raise EngineFileError(path, fld, f"{program}: is not a file")
        if not os.access(p, os.X_OK):
            raise EngineFileError(path, fld, f"{program}: is not executable (chmod +x?)")
        return str(p.resolve())
    if shutil.which(program) is None:
        raise EngineFileError(path, fld, f"{program!r}: no such program on PATH")
    return program


def _parse_command(path, folder: Path, fld: str, cmd) -> list:
    if not isinstance(cmd, list) or not cmd:
        raise EngineFileError(path, fld,
                              f"must be a non-empty list of strings, e.g. [\"./mysim\", "
                              f"\"{{scenario_json}}\", \"{{out_csv}}\"], got {cmd!r}"[:300])
    parsed = [_parse_argument(path, f"{fld}[{i}]", a) for i, a in enumerate(cmd)]
    if any(name for _, name in parsed[0]):
        raise EngineFileError(path, f"{fld}[0]",
                              "the program must be named literally (placeholders are for its arguments)")
    used = {name for arg in parsed for _, name in arg if name}
    for need, why in (("out_csv", "where to write the trajectory"), ("scenario_json", "what to simulate")):
        if need not in used:
            raise EngineFileError(path, fld, f"never mentions {{{need}}}: the command cannot know {why}")
    program = _resolve_program(path, folder, f"{fld}[0]", parsed[0][0][0])
    for i, arg in enumerate(parsed[1:], start=1):
        if len(arg) == 1 and arg[0][1] is None:
            _check_file_argument(path, folder, f"{fld}[{i}]", arg[0][0])
    return [[(program, None)]] + parsed[1:]


#: Suffixes of the files a command names as arguments (its script, its model, its data): an argument
#: ending in one names a file, which must then be in the engine file's folder (or be an absolute path).
FILE_SUFFIXES = frozenset(
    ".py .jl .js .mjs .ts .rb .pl .lua .r .m .sh .bash .jar .exe .dll .so .dylib .cs .csx .java .class .kt "
    ".wasm .json .toml .yaml .yml .xml .urdf .sdf .mjcf .csv .txt .dat .cfg .ini .mat .npz .npy".split())


def _check_file_argument(path, folder: Path, fld: str, text: str) -> None:
    """EngineFileError when a literal argument names a file (a relative path ``dir/x``, ``./x``, or a name
    with a file suffix, ``sim.py``) that does not exist: the command runs in a private working directory,
    so the file is looked up in the engine file's folder — a typo would otherwise fail every run."""
    if not text or text.startswith("-") or "://" in text or "=" in text:
        return
    p = Path(text)
    relative_path = "/" in text and not p.is_absolute() and not all(x.replace(".", "").isdigit()
                                                                      for x in text.split("/"))  # not 1/2
    if not (relative_path or p.suffix.lower() in FILE_SUFFIXES):
        return
    where = p if p.is_absolute() else folder / p
    if where.exists():
        return
    import difflib
    try:
        near = difflib.get_close_matches(p.name, [f.name for f in where.parent.iterdir()], n=1)
    except OSError:
        near = []
    hint = f"; did you mean {str(p.with_name(near[0]))!r}?" if near else ""
    looked = "" if p.is_absolute() else (f" (looked in {where.parent}: the command runs in a private "
                                         "working directory, and a file it names is taken from the engine "
                                         "file's folder)")
    raise EngineFileError(path, fld, f"{text}: no such file{looked}{hint}")


def _number(path, d: dict, key: str, fld: str, lo: float, hi: float, what: str):
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo < v <= hi:
        raise EngineFileError(path, fld, f"must be {what}, got {v!r}")
    return float(v)


def _string(path, d: dict, key: str, fld: str, default=None, nonempty=False):
    if key not in d:
        return default
    v = d[key]
    if not isinstance(v, str) or (nonempty and not v.strip()):
        hint = (f" (quote it: {key} = \"{v}\")"
                if isinstance(v, (int, float)) and not isinstance(v, bool) else "")
        raise EngineFileError(path, fld,
                              f"must be a{' non-empty' if nonempty else ''} string, got {v!r}{hint}")
    return v


def _hash_file(p: Path) -> str:
    h = hashlib.sha256()
    with open(p, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _program_files(folder: Path, commands: dict) -> dict:
    """Files inside the engine's folder that its commands name literally (the program, a script):
    their hashes go into the cache key, so rebuilding the engine invalidates its cached results."""
    out = {}
    root = folder.resolve()
    for parsed in commands.values():
        for arg in parsed:
            if len(arg) != 1 or arg[0][1] is not None or not arg[0][0]:
                continue
            p = Path(arg[0][0])
            p = (p if p.is_absolute() else folder / p)
            try:
                p = p.resolve()
                if p.is_file() and p.is_relative_to(root):
                    out[str(p)] = _hash_file(p)
            except OSError:
                continue
    return out


def folder_fingerprint(folder: Path) -> str:
    """SHA-256 of what under ``folder`` a run may depend on: every file's relative path and content (past
    FOLDER_MAX_FILES files or FOLDER_CONTENT_MAX_BYTES of content, its size and modification time), in a
    stable order. Hidden folders, ``__pycache__`` and rbcheck's results directories (their marker) are left
    out: they change with every sweep, not with the engine."""
    h = hashlib.sha256()
    files, content = 0, 0
    for root, dirs, names in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if not d.startswith(".") and d != "__pycache__"
                         and not (Path(root) / d / ".rbcheck-results.json").exists())
        for name in sorted(names):
            p = Path(root) / name
            if name.startswith(".") or not p.is_file():
                continue
            try:
                st = p.stat()
            except OSError:
                continue
            files += 1
            h.update(str(p.relative_to(folder)).encode())
            if files <= FOLDER_MAX_FILES and content + st.st_size <= FOLDER_CONTENT_MAX_BYTES:
                content += st.st_size
                try:
                    h.update(_hash_file(p).encode())
                except OSError:
                    h.update(b"<unreadable>")
            else:
                h.update(f"{st.st_size}:{st.st_mtime_ns}".encode())
    return h.hexdigest()


def _invariance_findings(path, items, where: str) -> tuple:
    """The variant's declared invariance findings (``[[variants.NAME.invariance_findings]]``: transform,
    within = {SIZE = [low, high], ...}, quantities (optional), reason; engines.base.InvarianceFinding,
    docs/invariance.md "Declared findings"); EngineFileError naming the entry's field when one is bad."""
    from cross_checks.core.quantities import QUANTITIES
    from cross_checks.engines.base import InvarianceFinding
    from cross_checks.scenario.transforms import TRANSFORM_PARAMETERS
    if not isinstance(items, list):
        raise EngineFileError(path, where, "must be an array of tables [[" + where + "]], got " + repr(items))
    out = []
    for i, item in enumerate(items):
        at = f"{where}[{i}]"
        if not isinstance(item, dict):
            raise EngineFileError(path, at, f"must be a table, got {item!r}")
        _check_keys(path, item, _FINDING, at + ".")
        kind = item.get("transform")
        if kind not in TRANSFORM_PARAMETERS:
            raise EngineFileError(path, f"{at}.transform",
                                  f"must be one of {', '.join(TRANSFORM_PARAMETERS)}, got {kind!r}")
        names = TRANSFORM_PARAMETERS[kind]
        within = item.get("within")
        if not isinstance(within, dict) or not within:
            raise EngineFileError(path, f"{at}.within", f"must bound at least one of {kind}'s sizes "
                                  f"({', '.join(names)}) as {{ SIZE = [low, high] }} (never the whole "
                                  f"transform), got {within!r}")
        ranges = []
        for name, rng in within.items():
            ok = (name in names and isinstance(rng, list) and len(rng) == 2
                  and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                          for v in rng) and rng[0] <= rng[1])
            if not ok:
                raise EngineFileError(path, f"{at}.within.{name}", f"must be a size of {kind} "
                                      f"({', '.join(names)}) with a range [low, high] of finite numbers, "
                                      f"low <= high, got {rng!r}")
            ranges.append((name, float(rng[0]), float(rng[1])))
        quantities = item.get("quantities", list(QUANTITIES))
        if (not isinstance(quantities, list) or not quantities
                or any(q not in QUANTITIES for q in quantities)):
            raise EngineFileError(path, f"{at}.quantities",
                                  f"must be a non-empty list of {', '.join(QUANTITIES)}, got {quantities!r}")
        reason = item.get("reason")
        if not isinstance(reason, str) or not reason.strip():
            raise EngineFileError(path, f"{at}.reason", "missing (required): the sentence that explains the "
                                  "finding (what the engine does, what was measured)")
        out.append(InvarianceFinding(kind, tuple(ranges), reason.strip(), tuple(quantities)))
    return tuple(out)


def load_engine_file(path) -> ExternalEngine:
    """Read and validate an engine file. Raises EngineFileError (``FILE: FIELD: REASON``)."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise EngineFileError(path, "", "no such file") from None
    except IsADirectoryError:
        raise EngineFileError(path, "", "is a directory, not an engine file") from None
    except OSError as exc:
        raise EngineFileError(path, "", f"cannot read: {exc}") from None
    try:
        raw = tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise EngineFileError(path, "", f"is not UTF-8 text: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise EngineFileError(path, "", f"TOML syntax error: {exc}") from None
    _check_keys(path, raw, _TOP, "")
    name = _string(path, raw, "name", "name")
    if name is None:
        raise EngineFileError(path, "name", "missing (required): the engine name, used as NAME:VARIANT")
    if not NAME_RE.match(name):
        raise EngineFileError(path, "name",
                              "must match [a-z0-9_]+ (lower-case letters, "
                              f"digits, underscore), got {name!r}")
    version = _string(path, raw, "version", "version", default="", nonempty=True)
    description = _string(path, raw, "description", "description", default="")
    timeout = (_number(path, raw, "timeout", "timeout", 0.0, MAX_TIMEOUT_S,
                       f"a number of seconds in (0, {MAX_TIMEOUT_S:g}]")
               if "timeout" in raw else DEFAULT_TIMEOUT_S)
    forms = raw.get("body_forms", [])
    from cross_checks.engines import BODY_FORMS
    if not isinstance(forms, list) or any(not isinstance(f, str) or f not in BODY_FORMS for f in forms):
        known = ", ".join(repr(f) for f in BODY_FORMS)
        raise EngineFileError(path, "body_forms", "must be a list of the body forms the command reads from "
                              f"the resolved scenario ({known}), got {forms!r}")
    if "variants" not in raw:
        raise EngineFileError(path, "variants", "missing (required): at least one [variants.NAME] table")
    vt = raw["variants"]
    if not isinstance(vt, dict) or not vt:
        raise EngineFileError(path, "variants", "must contain at least one [variants.NAME] table")
    folder = path.resolve().parent
    variants, commands = {}, {}
    for vname, spec in vt.items():
        where = f"variants.{vname}"
        if not NAME_RE.match(vname):
            raise EngineFileError(path, where, f"variant name must match [a-z0-9_]+, got {vname!r}")
        if not isinstance(spec, dict):
            raise EngineFileError(path, where, f"must be a table [{where}], got {spec!r}")
        _check_keys(path, spec, _VARIANT, where + ".")
        if "order" not in spec:
            raise EngineFileError(path, f"{where}.order",
                                  "missing (required): the global order of accuracy "
                                  "its author claims (e.g. 1 for semi-implicit Euler)")
        order = _number(path, spec, "order", f"{where}.order", 0.0, 20.0, "a number in (0, 20]")
        desc = _string(path, spec, "description", f"{where}.description", default="")
        if "command" not in spec:
            raise EngineFileError(path, f"{where}.command",
                                  "missing (required): the command that runs one simulation")
        commands[vname] = _parse_command(path, folder, f"{where}.command", spec["command"])
        precision = _string(path, spec, "precision", f"{where}.precision", default="float64")
        if precision not in tol.MACHINE_EPSILON:
            raise EngineFileError(path, f"{where}.precision",
                                  f"must be one of {', '.join(tol.MACHINE_EPSILON)} (the format its steps "
                                  f"compute in), got {precision!r}")
        findings = _invariance_findings(path, spec.get("invariance_findings", []),
                                        f"{where}.invariance_findings")
        traits = (None if precision == "float64" and not findings
                  else dataclasses.replace(DEFAULT_TRAITS, precision=precision, invariance_findings=findings))
        variants[vname] = Variant(order, desc, traits=traits)
    sha = hashlib.sha256(data).hexdigest()
    engine = ExternalEngine(path.resolve(), name, version, description, timeout, variants, commands, sha,
                            _program_files(folder, commands), folder_fingerprint(folder))
    engine.body_forms = frozenset(forms)
    return engine


class ExternalEngine(EngineAdapter):
    """An engine file as an adapter (picklable: plain data, so sweep workers receive it)."""

    #: The body forms its command reads from the resolved scenario (body.com, body.parts: docs/engines.md),
    #: as its file declares them (``body_forms = [...]``); none by default: an engine file written before
    #: they existed reads a body at its COM, and a scenario that needs another form is "cannot express" for
    #: it (never a wrong motion blamed on it).
    body_forms: frozenset = frozenset()

    def __init__(self, path: Path, name: str, version: str, description: str, timeout_s: float,
                 variants: dict, commands: dict, sha256: str, program_hashes: dict, folder_sha256: str = ""):
        self.path, self.name, self._version, self.description = Path(path), name, version, description
        self.timeout_s, self.variants, self.commands = timeout_s, variants, commands
        self.sha256, self.program_hashes, self.folder_sha256 = sha256, program_hashes, folder_sha256

    @property
    def folder(self) -> Path:
        return self.path.parent

    @property
    def source(self) -> str:
        return f"engine file {self.path}"

    def version(self) -> str:
        return self._version or "unversioned"

    def source_files(self) -> list:
        return [self.path] + [Path(p) for p in sorted(self.program_hashes)]

    def cache_token(self) -> str:
        """The engine file, the programs it names and every file under its folder, as hashed when the
        file was loaded."""
        return (self.sha256 + "".join(f"|{k}={v}" for k, v in sorted(self.program_hashes.items()))
                + f"|folder={self.folder_sha256}")

    def provenance(self) -> dict:
        return {"engine_file": str(self.path), "engine_file_sha256": self.sha256,
                "programs_sha256": dict(self.program_hashes), "folder_sha256": self.folder_sha256,
                "timeout_s": self.timeout_s}

    def same_as(self, other) -> bool:
        return isinstance(other, ExternalEngine) and (other.path, other.sha256) == (self.path, self.sha256)

    def argv(self, variant: str, values: dict) -> list:
        """The command of ``variant`` with its placeholders replaced by ``values`` (strings); an argument that
        is literally a file of the engine file's folder (the program, a script) as its absolute path, since
        the command runs in a private working directory."""
        out = []
        for arg in self.commands[variant]:
            text = "".join(lit + (values[name] if name else "") for lit, name in arg)
            if len(arg) == 1 and arg[0][1] is None and text and not os.path.isabs(text):
                local = self.folder / text
                if ("/" in text or local.is_file()) and local.exists():
                    text = str(local.resolve())
            out.append(text)
        return out

    def simulate(self, scenario, variant: str, dt_s: float, n_steps: int) -> Run:
        from cross_checks.scenario.resolved import resolved_json
        T = scenario.duration_s if n_steps == scenario.n_steps(dt_s) else n_steps * dt_s
        run_dir = Path(tempfile.mkdtemp(prefix=f"rbcheck-{self.name}-"))
        try:
            work, out_dir = run_dir / "work", run_dir / "out"   # the command's working directory; its output
            work.mkdir()
            out_dir.mkdir()
            json_path, out_csv = run_dir / "scenario.json", out_dir / "trajectory.csv"
            json_path.write_text(resolved_json(scenario, dt_s, T), encoding="utf-8")
            argv = self.argv(variant,
                             {"scenario_json": str(json_path), "dt": repr(float(dt_s)), "steps": str(n_steps),
                              "duration": repr(float(T)), "out_csv": str(out_csv),
                              "engine_dir": str(self.folder.resolve())})
            try:
                rc, timed_out, words = processes.run_command(argv, work, self.timeout_s, private=run_dir)
            except processes.CannotStart as exc:
                raise EngineError(str(exc)) from None
            where = f"{self.name}:{variant} at Δt = {dt_s:g} s"
            said = f" — it said: {words}" if words else " (it printed nothing)"
            if timed_out:
                raise EngineError(f"{where}: no result within the time limit of {self.timeout_s:g} s "
                                  f"(set `timeout` in {self.path.name}); the command was killed{said}")
            if rc != 0:
                raise EngineError(f"{where}: the command {processes.exit_words(rc)}{said}")
            if not out_csv.is_file():
                elsewhere = sorted(p.name for p in work.glob("*.csv"))
                if elsewhere:
                    raise EngineError(f"{where}: the command wrote no CSV at {{out_csv}} but "
                                      f"{', '.join(elsewhere[:3])} in its working directory (write "
                                      f"the trajectory to the path {{out_csv}} gives){said}")
            return _read_output(out_csv, scenario, dt_s, n_steps, where, said)
        finally:
            shutil.rmtree(run_dir, ignore_errors=True)


def _read_output(out_csv: Path, scenario, dt_s: float, n_steps: int, where: str, said: str) -> Run:
    """The trajectory the command wrote, through the shared reader (columns by name), checked against
    the contract: steps + 1 rows on the Δt grid from t = 0, a finite first row; a later non-finite or
    blown-up row is a divergence."""
    from cross_checks.core.trajectory import TrajectoryError, read_columns
    if not out_csv.is_file():
        raise EngineError(f"{where}: the command exited 0 but wrote no CSV at {{out_csv}}{said}")
    size = out_csv.stat().st_size
    if size > (n_steps + 2) * MAX_CSV_BYTES_PER_ROW:
        raise EngineError(f"{where}: the CSV is {size} bytes, more than {MAX_CSV_BYTES_PER_ROW} bytes per "
                          f"row for {n_steps + 1} rows: not a trajectory")
    try:
        t, y, _ = read_columns(out_csv)
    except TrajectoryError as exc:
        msg = str(exc).replace(str(out_csv), "{out_csv}")
        raise EngineError(f"{where}: the CSV is not a trajectory: {msg}{said}") from None
    n_rows = len(t)
    bad = bad_rows(y)
    if n_rows < n_steps + 1 and not np.any(bad):
        raise EngineError(f"{where}: the CSV has {n_rows} rows, expected {n_steps + 1} "
                          f"(t = 0 and each of the {n_steps} steps){said}")
    if n_rows > n_steps + 1:
        raise EngineError(f"{where}: the CSV has {n_rows} rows, more than the {n_steps + 1} of t = 0 and "
                          f"{n_steps} steps{said}")
    grid = dt_s * np.arange(n_rows)
    off = np.abs(t - grid) > 0.5 * dt_s
    if np.any(off):
        k = int(np.argmax(off))
        raise EngineError(f"{where}: row {k} (line {k + 2}) has t = {float(t[k])!r}, expected "
                          f"{float(grid[k])!r} (one row per step of {dt_s:g} s from t = 0)")
    if bad[0]:
        raise EngineError(f"{where}: the first row (t = 0) is not a finite state{said}")
    note = _initial_state_note(y[0], scenario)
    if np.any(bad):
        k = int(np.argmax(bad))
        return diverged(y[:k], dt_s,
                        f" ({blowup_words(y[k])}, written by the engine)" + (f"; {note}" if note else ""))
    return Run(dt_s * np.arange(n_steps + 1), y, None, note)


def _initial_state_note(y0, scenario) -> str:
    """A hint when the first row is not the scenario's initial state (the engine misread the JSON?)."""
    from reference_sim.quaternion import geodesic_angle
    ref = scenario.problem.initial_packed()
    scale = max(1.0, float(np.max(np.abs(ref))))
    parts = []
    for name, sl in (("position", slice(0, 3)), ("velocity", slice(3, 6)),
                     ("angular velocity", slice(10, 13))):
        d = float(np.max(np.abs(y0[sl] - ref[sl])))
        if d > tol.ENGINE_FILE_INITIAL_STATE_REL * scale:
            parts.append(f"{name} by {d:.3g}")
    qn = float(np.linalg.norm(y0[6:10]))
    ang = float(geodesic_angle(ref[6:10], y0[6:10] / qn)) if qn > 0 else math.pi
    if ang > tol.ENGINE_FILE_INITIAL_STATE_REL:
        parts.append(f"orientation by {ang:.3g} rad")
    if not parts:
        return ""
    return ("its first row differs from the scenario's initial state (" + ", ".join(parts)
            + "): does the engine read the resolved JSON as documented?")

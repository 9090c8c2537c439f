"""The compiled engines' runtimes: JAX started once per process (float64, its persistent compilation cache)
and refused in a process forked after it started, Warp initialised once (its kernel cache, its output
silenced, a damaged cache entry compiled again), and what their adapters share: counters of compilations
and seconds (:class:`Stats`), the values a host callback inside compiled code looks up (:class:`Registry`),
batch sizes padded to a power of two (a handful of compiled executables serve every batch size), and the
Warp engines' shared machinery (:class:`WarpEngine`) and the JAX engines' (:class:`JaxEngine`,
:class:`JaxWorld`).

Both are started on first use only: a sweep's parent forks its workers, and a running JAX backend or Warp
runtime does not survive a fork.
"""
from __future__ import annotations

import contextlib
import functools
import importlib
import io
import itertools
import os
import sys
import threading
import time
import warnings

import numpy as np

from cross_checks.core.files import kernel_cache_dir
from cross_checks.engines import install
from cross_checks.engines.base import EngineError
from cross_checks.engines.install import quiet_fd2
from cross_checks.engines.world import World, WorldEngine
from reference_sim.simulate import bad_rows

__all__ = ["start_jax", "refuse_forked_jax", "start_warp", "Stats", "Registry", "power_of_two",
           "stack_trees", "recorded", "chunk_rows", "WarpEngine", "JaxEngine", "JaxWorld"]


@functools.lru_cache(maxsize=1)
def start_jax():
    """``jax`` with float64 on (``jax_enable_x64``: process-global, so every JAX engine of the process
    computes in float64) and its persistent compilation cache in ``core.files.kernel_cache_dir("jax")``,
    shared by the JAX engines. Called on first use only: a sweep's parent must not start JAX (it forks)."""
    import jax
    jax.config.update("jax_enable_x64", True)
    try:
        folder = kernel_cache_dir("jax")
        folder.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", str(folder))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    except OSError:   # pragma: no cover - an unwritable cache directory only costs compile time
        pass
    return jax


#: True in a process forked after JAX's backend had started in its parent (set in the child at fork).
_FORKED_AFTER_JAX = [False]


def _after_fork_in_child() -> None:
    if "jax" in sys.modules:
        from jax._src import xla_bridge
        _FORKED_AFTER_JAX[0] = bool(xla_bridge.backends_are_initialized())


os.register_at_fork(after_in_child=_after_fork_in_child)


def refuse_forked_jax(words: str) -> None:
    """:class:`EngineError` with ``words`` in a process forked after JAX started in its parent: a running JAX
    backend does not survive fork (its threads are gone) and its first computation would hang."""
    if _FORKED_AFTER_JAX[0]:
        raise EngineError(words)


def start_warp(cache: str, log_level: str, quiet: bool = False):
    """``warp``, initialised on first use with its kernel cache in ``core.files.kernel_cache_dir(cache)`` (set
    before ``wp.init``), ``wp.config.log_level = wp.<log_level>`` and ``wp.config.quiet``; fd 2 silenced
    meanwhile (Warp's runtime prints there that no CUDA driver exists).

    A cache is a cache (docs/hardening.md): a folder where nothing can be written is replaced by a private
    one for the run; a module whose cached files cannot be loaded (an object cut in half: "Failed to load CPU
    module", a damaged metadata file) has its folder removed, said once, and is compiled again."""
    from cross_checks.core.files import usable_cache_dir
    folder = usable_cache_dir(kernel_cache_dir(cache), f"{cache}'s kernel")   # read-only, full: skipped, said
    with quiet_fd2():
        import warp as wp
        wp.config.kernel_cache_dir = str(folder)
        wp.config.quiet = quiet
        wp.config.log_level = getattr(wp, log_level)
        wp.init()
    module_class = getattr(getattr(getattr(wp, "_src", None), "context", None), "Module", None)
    load = getattr(module_class, "load", None)
    if load is not None and not getattr(load, "rbcheck_recompiles_damaged", False):
        import json
        import shutil
        import sys

        def load_or_recompile(self, device, block_dim=None, binary_path=None, output_arch=None,
                              meta_path=None):
            try:
                return load(self, device, block_dim, binary_path, output_arch, meta_path)
            except Exception as exc:
                damaged = (isinstance(exc, json.JSONDecodeError) or "Failed to load" in str(exc)
                           or "metadata file" in str(exc))   # not a build error of the kernel's own
                if binary_path is not None or not damaged:   # (binary_path: the caller's, not the cache)
                    raise
                try:
                    where = os.path.join(wp.config.kernel_cache_dir, self.get_module_identifier(
                        block_dim if block_dim is not None else self.options["block_dim"]))
                except Exception:  # noqa: BLE001 - Warp's internals changed: its own error stands
                    raise exc from None
                if not os.path.isdir(where):
                    raise
                print(f"rbcheck: {cache}'s kernel cache entry {where} could not be loaded ({exc}); removed, "
                      "compiling it again", file=sys.stderr, flush=True)
                shutil.rmtree(where, ignore_errors=True)
                return load(self, device, block_dim, binary_path, output_arch, meta_path)
        load_or_recompile.rbcheck_recompiles_damaged = True
        module_class.load = load_or_recompile
    return wp


class Stats(dict):
    """An adapter's counters in this process (compilations, wall seconds, steps), zeroed by :meth:`reset`."""

    def __init__(self, **zeros):
        super().__init__(zeros)
        self.zeros = zeros

    def reset(self) -> None:
        self.update(self.zeros)

    @contextlib.contextmanager
    def timing(self, key: str):
        """Adds the block's wall seconds to ``self[key]`` (nothing when it raises)."""
        t0 = time.perf_counter()
        yield
        self[key] += time.perf_counter() - t0


class Registry(dict):
    """Values held under fresh integer keys for the duration of a block: what a host callback inside compiled
    code (``jax.pure_callback``) looks up by the key it was given."""

    def __init__(self):
        super().__init__()
        self._keys = itertools.count(1)
        self._lock = threading.Lock()

    @contextlib.contextmanager
    def holding(self, value):
        """``np.int64(key)`` of ``value`` for the block; the entry is dropped after it."""
        with self._lock:
            key = next(self._keys)
            self[key] = value
        try:
            yield np.int64(key)
        finally:
            self.pop(key, None)


def power_of_two(n: int) -> int:
    """The batch size ``n`` (≥ 1) runs or rows are padded to: the next power of two, so that a handful of
    compiled executables serve every batch size."""
    return 1 << (int(n) - 1).bit_length()


def stack_trees(trees, which):
    """A batch of pytrees of one structure (a JAX engine's models: MJX Models, jaxsim models) for
    ``jax.vmap`` over its first axis: ``which`` (B,) indexes each body's tree in the distinct ``trees``; every
    leaf is stacked per body on the host (one transfer per leaf when the executable is called). Every leaf
    batched, even where all bodies share it: one executable serves any mix of bodies of a structure (Δt, mass,
    inertia traced), and jaxsim's vmapped step runs ~10x faster that way than with its model shared
    (measured at N
    = 1024, interleaved in one process: 0.17 against 1.6 CPU s for 100 steps; MJX's the same either way)."""
    import jax
    which = np.asarray(which, dtype=int)
    return jax.tree.map(lambda *xs: np.stack([np.asarray(x) for x in xs])[which], *trees)


def recorded(step, read, rows: int):
    """``loop(state, count) -> (state, records (rows, 13))``: ``count`` (traced, at most ``rows``) steps of
    ``step(state)`` in one ``lax.fori_loop``, ``read(state)`` (13,) recorded after each (the rest zeros): the
    compiled loop of a JAX engine's chunk."""
    import jax

    def loop(state, count):
        def body(i, carry):
            state, out = carry
            state = step(state)
            return state, out.at[i].set(read(state))
        return jax.lax.fori_loop(0, count, body, (state, jax.numpy.zeros((rows, 13))))
    return loop


#: Rows (body-steps) a compiled chunk records at most: its states buffer is (bodies, steps, 13) float64, so
#: 2**17 rows are 13.6 MB, written and copied to the host per call.
CHUNK_ROWS = 1 << 17


def chunk_rows(batch: int, longest: int) -> int:
    """The steps of a compiled chunk's states buffer for ``batch`` bodies: at most ``longest`` (the engine's
    longest chunk), at most :data:`CHUNK_ROWS` rows in all (a power of two, at least 64): a batch of a
    thousand bodies records 128 steps a call, a sweep's ladder of a few runs ``longest``."""
    fit = max(64, 1 << max(0, (CHUNK_ROWS // max(1, int(batch))).bit_length() - 1))
    return int(min(int(longest), fit))


class WarpEngine(WorldEngine):
    """A :class:`~cross_checks.engines.world.WorldEngine` on NVIDIA Warp (MuJoCo Warp, Newton), declared by
    its fields: :meth:`version` and the install checks from package metadata and import specs only (Warp
    not started: a sweep's parent forks its workers); on first use (:meth:`modules`) Warp started by
    :func:`start_warp` (the kernel cache named after the engine, ``warp_log``, ``warp_quiet``), then
    ``imports``; ``stats``, the subclass's counters (a :class:`Stats` with ``compilations`` and
    ``compile_seconds``), and ``warmed``, the seconds of each kernel load (:meth:`warm`)."""

    runs_on = ("warp", "warp-lang")
    warp_log: str = "LOG_WARNING"
    warp_quiet: bool = False
    imports: tuple = ()
    stats: Stats

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        cls._modules, cls.warmed = [], {}

    def version(self) -> str:
        install.check_installed(self.distribution, f"pip install 'rbcheck[{self.extra}]'", (self.runs_on,))
        return install.release(self.distribution, self.runs_on)

    def modules(self) -> tuple:
        """``(warp, *imports)``, imported once, fd 2 silenced (an import failure an ImportError with the
        distribution's version: install.first_import)."""
        if not self._modules:
            self.version()
            with install.first_import(self.distribution), quiet_fd2():
                wp = start_warp(self.name, self.warp_log, self.warp_quiet)
                self._modules[:] = [wp, *map(importlib.import_module, self.imports)]
        return tuple(self._modules)

    def start_for_repro(self) -> None:
        """Warp and the engine started as the adapter starts them before ``rbcheck repro`` runs a script's
        world in this process (the world imports Warp itself); EngineError with the engine's words."""
        install.engine_or_error(self.modules)

    def warm(self, key, load) -> None:
        """``load()`` (a variant's kernels compiled, or loaded from Warp's kernel cache) once per ``key`` in
        this process, its wall seconds kept in ``warmed`` and counted in ``stats``."""
        if key not in self.warmed:
            t0 = time.perf_counter()
            load()
            self.warmed[key] = time.perf_counter() - t0
            self.stats["compilations"] += 1
            self.stats["compile_seconds"] += self.warmed[key]


class JaxEngine(WorldEngine):
    """A :class:`~cross_checks.engines.world.WorldEngine` on JAX (jaxsim, Brax, MJX), declared by its fields:
    ``version()`` and the install checks from package metadata and import specs only (``module``, and
    ``needs``: the (module, distribution) pairs it runs on; nothing imported: a sweep's parent must not start
    JAX before it forks); JAX started rbcheck's way and ``imports`` imported on first use (:meth:`modules`);
    a process forked after JAX started in its parent refused (:meth:`usable`); the executables compiled
    ahead of time once per key (:meth:`compiled`), and the counters of each subclass in this process
    (``stats``, :meth:`timings`): ``compilations``, ``compile_seconds`` (tracing, lowering and XLA
    compilation, persistent-cache loads included), ``step_seconds`` (inside compiled calls, host callbacks
    included), ``body_steps`` (steps × the bodies they advanced); ``per_executable``: the compile seconds
    of each executable by name."""

    needs: tuple = (("jax", "jax"), ("jaxlib", "jaxlib"))
    #: Modules imported on first use, after JAX started (their stdout silenced: mujoco.mjx's "Failed to
    #: import warp"), and their warnings too with ``quiet_warnings`` (brax's "not actively maintained").
    imports: tuple = ()
    quiet_warnings: bool = False
    #: Bodies per vmapped batch of a rollout at most (padded to a power of two, so that batch sizes share
    #: executables): a thousand bodies in one call, as an engine's own vmapped loop runs them.
    max_batch: int = 1024
    harness = (*WorldEngine.harness, "cross_checks.engines.jax_forces")

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        cls.stats = Stats(compilations=0, compile_seconds=0.0, step_seconds=0.0, body_steps=0)
        cls.per_executable, cls._executables, cls._modules = {}, {}, []
        cls.lock = threading.RLock()

    def version(self) -> str:
        install.check_installed(self.distribution, f"pip install 'rbcheck[{self.extra}]'",
                                needs=((self.module or self.distribution, self.distribution), *self.needs))
        return install.release(self.distribution, self.runs_on)

    def modules(self) -> tuple:
        """``(jax, jax.numpy, *imports)``, imported once (:meth:`version` first; an import failure an
        ImportError with the distribution's version: install.first_import), float64 checked on after them
        (``import jaxsim`` sets it too). The process's warning filters and ``warnings.showwarning`` are
        restored after the imports: ``import jaxsim`` sets a filter "once" for every warning and a
        ``showwarning`` that prints any site-packages module's warning to stdout (Brax's deprecations among
        them, in the middle of a sweep's output)."""
        if not self._modules:
            self.version()
            with install.first_import(self.distribution), contextlib.redirect_stdout(io.StringIO()), \
                    warnings.catch_warnings():
                if self.quiet_warnings:
                    warnings.simplefilter("ignore")
                jax = start_jax()
                self._modules[:] = [jax, importlib.import_module("jax.numpy"),
                                    *map(importlib.import_module, self.imports)]
            if not jax.config.jax_enable_x64:
                raise EngineError(f"{self.name}: jax_enable_x64 is off after the engine's import; rbcheck "
                                  "needs float64")
        return tuple(self._modules)

    def usable(self) -> tuple:
        """:meth:`modules` (an ImportError as an EngineError), or EngineError in a process forked after JAX
        started in its parent (a running JAX backend does not survive fork: its first computation would
        hang)."""
        refuse_forked_jax(f"{self.name} cannot run in a process forked after JAX started in its parent (a "
                          "running JAX backend does not survive fork: it would hang); run the sweep with "
                          "--jobs 1 from there, or from a process that has not run JAX")
        return install.engine_or_error(self.modules)

    def compiled(self, key, make, *args, name: str = ""):
        """``jax.jit(make()).lower(*args).compile()``, once per ``key`` and shapes of the arguments' leaves
        (its time counted, under ``name`` too); EngineError with XLA's words when it refuses."""
        jax = start_jax()
        key = (key, tuple(np.shape(a) for a in jax.tree_util.tree_leaves(args)))
        with self.lock:
            exe = self._executables.get(key)
            if exe is None:
                t0 = time.perf_counter()
                try:
                    exe = jax.jit(make()).lower(*args).compile()
                except Exception as exc:  # noqa: BLE001 - the engine or XLA refusing the computation
                    raise EngineError(f"{self.name}/XLA could not compile the step: {type(exc).__name__}: "
                                      f"{exc}") from None
                seconds = time.perf_counter() - t0
                self.stats["compile_seconds"] += seconds
                self.stats["compilations"] += 1
                self.per_executable[name] = self.per_executable.get(name, 0.0) + seconds
                self._executables[key] = exe
        return exe

    def timings(self) -> dict:
        """This process's counters (see the class docstring)."""
        return dict(self.stats)

    @property
    def compile_seconds(self) -> float:
        return self.stats["compile_seconds"]


class JaxWorld(World):
    """A world of a :class:`JaxEngine` (``engine``) whose ``rollout`` is its compiled loop: ``run(n_steps,
    harness)``, whose seconds outside the compiled calls (the forces' arrays, stacking the models,
    compiling) are rbcheck's (``host_s``), the calls' own (``engine.stats["step_seconds"]``) the engine's."""

    engine: JaxEngine

    def rollout(self, n_steps, harness):
        t0, stepped = time.perf_counter(), self.engine.stats["step_seconds"]
        try:
            return self.run(n_steps, harness)
        finally:
            self.host_s += time.perf_counter() - t0 - (self.engine.stats["step_seconds"] - stepped)

    def chunks(self, call, n_max: int, rows: int, idx, out, finite_only: bool = False) -> None:
        """Steps 1..n_max of the bodies ``idx`` (B) into ``out[:, idx]``, ``rows`` a call of ``call(count)``
        (``count`` steps of the compiled loop, its state carried) -> the chunk's states (≥ B, ≥ count, 13),
        timed and counted; the batch stops after the chunk after which each body has ended (its request's
        steps: ``self.ends``) or blown up (``bad_rows`` in the chunk; ``finite_only``: a non-finite last
        row)."""
        ends, done, k = np.array([self.ends[i] for i in idx]), np.zeros(len(idx), dtype=bool), 0
        while k < n_max and not done.all():
            count = min(rows, n_max - k)
            with self.engine.stats.timing("step_seconds"):
                chunk = np.asarray(call(count))[:len(idx), :count]
            self.engine.stats["body_steps"] += count * len(idx)
            out[k:k + count, idx] = chunk.transpose(1, 0, 2)
            with np.errstate(all="ignore"):
                bad = ~np.isfinite(chunk[:, -1]).all(-1) if finite_only else bad_rows(chunk).any(axis=1)
            done |= bad | (ends <= k + count)
            k += count

"""The engines a command runs: ``--engine-file`` registered before it, ``--engines`` resolved to the
variants to run (unknown, unavailable or broken required engines refused), and ``--dask``'s executor
(rbcheck sweep and rbcheck fuzz)."""
from __future__ import annotations

import contextlib
import socket

from cross_checks.cli.errors import BadInput


def use_engine_files(paths) -> None:
    from cross_checks.engines import load_engine_files
    from cross_checks.engines.external import EngineFileError
    try:
        load_engine_files(paths)
    except EngineFileError as exc:
        raise BadInput(str(exc)) from None


def resolve_engines(specs):
    """``--engines`` values -> (variants to run, {variant: why skipped}) ; BadInput for unknown or
    explicitly requested unavailable ones."""
    from cross_checks.engines import UnknownVariant, all_variants, engine_variants, resolve

    _refuse_unusable_required_engines()
    infos = {v.name: v for v in all_variants()}
    if not specs:
        run = [n for n, v in infos.items() if v.available]
        skipped = {n: v.reason for n, v in infos.items() if not v.available}
        return run, skipped
    out = []
    for spec in (x for s in specs for x in s.split(",") if x):
        try:
            names = [f"{spec}:{v}" for v in engine_variants(spec)] if ":" not in spec else [spec]
        except UnknownVariant as exc:
            raise BadInput(f"--engines: {exc}") from None
        if not names:
            raise BadInput(f"--engines {spec}: {infos[spec + ':*'].reason}")
        for n in names:
            try:
                n = resolve(n, strict=True)
            except UnknownVariant as exc:
                raise BadInput(f"--engines: {exc}") from None
            if not infos[n].available:
                raise BadInput(f"--engines {n}: {infos[n].reason}")
            if n not in out:
                out.append(n)
    return out, {}


def _refuse_unusable_required_engines() -> None:
    """BadInput when an engine rbcheck depends on (MuJoCo, PyBullet) cannot run here: a broken installation
    is repaired, never reported as "not installed" nor swept around."""
    from cross_checks.engines import unusable_required_engines
    broken = unusable_required_engines()
    if broken:
        engine, why = next(iter(broken.items()))
        raise BadInput(f"{engine} is required by rbcheck and cannot run here: {why}; "
                       "reinstall it (pip install --force-reinstall rbcheck, or pip "
                       "install -e . in a clone, installs the tested versions)")


def _refused_at_once(address: str) -> None:
    """Raise ConnectionRefusedError when nothing listens at a ``tcp://host:port`` scheduler address (Dask's
    client would retry a refused connection for its whole timeout, 10 s, before saying so); any other
    address, or any other outcome of the probe, is left to the client."""
    host, sep, port = address.removeprefix("tcp://").rpartition(":")
    if not address.startswith("tcp://") or not sep or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=2).close()
    except ConnectionRefusedError:
        raise
    except OSError:
        return


@contextlib.contextmanager
def dask_executor(address: str | None):
    """The executor of a client of the Dask scheduler at ``address`` (None without one), closed after."""
    if not address:
        yield None
        return
    try:
        from distributed import Client
    except ImportError:
        raise BadInput("--dask: the 'distributed' package is not installed; install the optional extra: "
                       "pip install -e '.[dask]'") from None
    try:
        _refused_at_once(address)
        client = Client(address, timeout=10)
    except (OSError, TimeoutError, ValueError) as exc:
        raise BadInput(f"--dask {address}: cannot connect to the Dask scheduler: {exc}") from None
    try:
        yield client.get_executor()
    finally:
        client.close()

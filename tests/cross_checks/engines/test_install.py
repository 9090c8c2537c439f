"""cross_checks.engines.install: the optional engines' plumbing (an installed package's files found without
importing it, an absent engine told from a broken one, fd 2 silenced, the first import's error, the
installed versions)."""
import os
import subprocess
import sys

import pytest

from cross_checks.engines import install
from cross_checks.engines.base import EngineError


def test_package_files_finds_an_installed_package_s_files_without_importing_it():
    files = install.package_files("json", pattern="*.py")
    assert any(f.name == "decoder.py" for f in files)
    assert install.package_files("json", "decoder.py") == [f for f in files if f.name == "decoder.py"]
    assert install.package_files("no_such_package_here") == []


def test_check_installed_tells_an_absent_engine_from_one_missing_what_it_runs_on(monkeypatch):
    versions = {"mysim": "1.0", "mylib": None}
    install.check_installed("mysim", "pip install mysim", version_of=versions.get)
    with pytest.raises(install.EngineNotInstalled, match=r"^othersim is not installed \(pip install x\)$"):
        install.check_installed("othersim", "pip install x", version_of=versions.get)
    said = "mysim 1.0 is installed but cannot be imported: mylib is missing"
    with pytest.raises(ImportError, match=said) as e:
        install.check_installed("mysim", "pip install mysim", (("json", "mylib"),), version_of=versions.get)
    assert not isinstance(e.value, install.EngineNotInstalled)


def test_quiet_fd2_silences_file_descriptor_2_for_the_block_only():
    code = ("import os\nfrom cross_checks.engines import install\nos.write(2, b'before ')\n"
            "with install.quiet_fd2():\n    os.write(2, b'hidden ')\nos.write(2, b'after')\n"
            "with install.quiet_fd2():\n    pass\nos.write(2, b'!')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert out.returncode == 0 and out.stderr == b"before after!"


def test_first_import_tells_a_broken_install_by_its_version_and_the_engine_s_words():
    with pytest.raises(ImportError, match=r"^mysim 1\.2 is installed but cannot be imported: "
                                          r"AttributeError: no attribute 'x'$") as e:
        with install.first_import("mysim", {"mysim": "1.2"}.get):
            raise AttributeError("no attribute 'x'")
    assert not isinstance(e.value, install.EngineNotInstalled)
    with install.first_import("mysim", {"mysim": "1.2"}.get):
        pass


def test_engine_or_error_makes_an_import_failure_an_engine_error():
    def broken():
        raise ImportError("mysim 1.2 is installed but cannot be imported: OSError: libmysim.so")

    with pytest.raises(EngineError, match="^mysim 1.2 is installed but cannot be imported: OSError"):
        install.engine_or_error(broken)
    assert install.engine_or_error(lambda: ("modules",)) == ("modules",)


def test_release_reads_the_installed_versions_from_package_metadata():
    from importlib.metadata import version as dist_version
    assert install.release("numpy") == dist_version("numpy")
    on_scipy = f"{dist_version('numpy')} (scipy {dist_version('scipy')})"
    assert install.release("numpy", ("scipy", "scipy")) == on_scipy
    assert install.release("no-such-distribution-rbcheck") == "unknown"


def test_optional_world_gives_the_world_module_or_empty_classes_to_build_on():
    import importlib
    module, error, world = install.optional_world("mujoco", "mujoco", "Bodies")
    assert error is None and module is importlib.import_module("mujoco")
    assert world is importlib.import_module("cross_checks.engines.worlds.mujoco")
    module, error, world = install.optional_world("rbcheck_no_such_engine", "mujoco", "Bodies", "FormBodies")
    assert module is None and isinstance(error, ImportError)
    assert isinstance(world.Bodies, type) and isinstance(world.FormBodies, type)

    class Built(world.Bodies):   # an adapter's class still loads on the placeholder
        pass
    assert issubclass(Built, world.Bodies) and not hasattr(world, "world")

"""The sweep on a Dask cluster (in-process LocalCluster) gives the local run's results exactly."""
import pytest

from cross_checks.cli import main
from cross_checks.scenario import parse_scenario
from cross_checks.sweep import run_sweep
from tests.helpers.scenarios import GRAVITY, scenario_toml
from tests.helpers.sweeps import result_rows as _rows

distributed = pytest.importorskip("distributed")

SPIN = scenario_toml("dask_spin", 0.5, 0.01, (0.02, 0.01, 0.005), description="torque-free asymmetric spin",
                     forces=GRAVITY)
VARIANTS = ["reference:course", "reference:rk4", "mujoco:euler"]


def test_dask_executor_gives_the_local_results(tmp_path, isolated_cache):
    pytest.importorskip("mujoco")
    sc = parse_scenario(SPIN, "spin.toml")
    run_sweep([sc], VARIANTS, tmp_path / "local", jobs=1, use_cache=False, progress=False)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        summary = run_sweep([sc], VARIANTS, tmp_path / "dask", use_cache=False, progress=False,
                            executor=client.get_executor())
    assert summary["run"]["runs"] == 9
    assert _rows(tmp_path / "dask") == _rows(tmp_path / "local")


def test_cli_dask_bad_address_is_bad_input(tmp_path, capsys):
    assert main(["sweep", "projectile", "--engines", "reference:course", "--dask", "tcp://127.0.0.1:1",
                 "--out", str(tmp_path / "r")]) == 2
    assert "cannot connect to the Dask scheduler" in capsys.readouterr().err


def test_cli_sweep_on_a_dask_scheduler(tmp_path, isolated_cache, capsys):
    f = tmp_path / "spin.toml"
    f.write_text(SPIN)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        rc = main(["sweep", str(f), "--engines", "reference:course", "reference:rk4", "--dask",
                   cluster.scheduler_address, "--no-cache", "--out", str(tmp_path / "r")])
    assert rc == 0, capsys.readouterr().err
    assert len(_rows(tmp_path / "r")) == 6 and (tmp_path / "r" / "index.html").is_file()

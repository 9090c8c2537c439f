"""The sweep on a Dask cluster (in-process LocalCluster) gives the local run's results exactly."""
import csv

import pytest

from cross_checks.cli import main
from cross_checks.scenario import parse_scenario
from cross_checks.sweep import run_sweep

distributed = pytest.importorskip("distributed")

SPIN = """
name = "dask_spin"
description = "torque-free asymmetric spin"
duration = 0.5
dt = 0.01
dt_ladder = [0.02, 0.01, 0.005]
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
angular_velocity = [0.3, 1.0, 0.2]
[forces]
gravity = [0.0, 0.0, -9.81]
"""
VARIANTS = ["reference:course", "reference:rk4", "mujoco:euler"]


def _rows(d):
    with open(d / "results.csv", newline="") as fh:
        return [{k: v for k, v in r.items() if k not in ("wall_s", "cached")} for r in csv.DictReader(fh)]


def test_dask_executor_gives_the_local_results(tmp_path, monkeypatch):
    pytest.importorskip("mujoco")
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
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


def test_cli_sweep_on_a_dask_scheduler(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("RBCHECK_CACHE_DIR", str(tmp_path / "cache"))
    f = tmp_path / "spin.toml"
    f.write_text(SPIN)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        rc = main(["sweep", str(f), "--engines", "reference:course", "reference:rk4", "--dask",
                   cluster.scheduler_address, "--no-cache", "--out", str(tmp_path / "r")])
    assert rc == 0, capsys.readouterr().err
    assert len(_rows(tmp_path / "r")) == 6 and (tmp_path / "r" / "index.html").is_file()

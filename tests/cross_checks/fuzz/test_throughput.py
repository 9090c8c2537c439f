"""The fuzz's throughput for rbcheck bench: cases/s per engine, measured in one run, ratios against MuJoCo."""
import pytest

from cross_checks.fuzz.throughput import format_fuzz, fuzz_throughput


@pytest.mark.slow
def test_throughput_reports_every_engine_against_mujoco_measured_in_the_same_run():
    r = fuzz_throughput(quick=True)
    assert r["cases"] > 0 and r["wall_s"] > r["shared_s"] > 0
    assert set(r["per_engine"]) == {"reference", "mujoco", "pybullet"}
    assert r["per_engine"]["mujoco"]["vs_mujoco"] == pytest.approx(1.0)
    assert all(d["case_variants_per_s"] > 0 for d in r["per_engine"].values())
    text = format_fuzz(r)
    assert "vs MuJoCo" in text and "pybullet" in text and "10,000" in text
    assert (r["cpu_s"] > 0
            and r["campaign_cases_600s_2_cores"] == pytest.approx(1200.0 * r["cases"] / r["cpu_s"]))

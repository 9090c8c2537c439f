"""`rbcheck bench` measures Drake's single-trajectory cost beside MuJoCo's through the same adapter
interface, and says so when Drake is not installed (its keys are then None, the rest unchanged)."""
import pytest

from cross_checks import bench


def test_drake_is_measured_beside_mujoco_through_the_adapters():
    pytest.importorskip("pydrake")
    through_adapter, constant_force = bench.drake_single_us(200, 1)
    from cross_checks.engines import mujoco_engine
    assert through_adapter > 0 and constant_force > 0 and bench.adapter_single_us(mujoco_engine, "euler", 200, 1) > 0


def test_without_drake_the_keys_are_none_and_the_table_says_why(monkeypatch):
    from cross_checks.engines import drake_engine
    monkeypatch.setattr(drake_engine, "pydrake", None)
    assert bench.drake_single_us(10, 1) == (None, None)
    r = {"reference_course_body_steps_per_s": 1.0, "reference_expmap_gyro_body_steps_per_s": 1.0,
         "mujoco_multibody_body_steps_per_s": 1.0, "mujoco_rollout_body_steps_per_s": 1.0,
         "pybullet_body_steps_per_s": 1.0, "n_bodies": {"reference": 1, "mujoco": 1, "mujoco_rollout": 1, "pybullet": 1},
         "mujoco_best_body_steps_per_s": 1.0, "reference_single_us_per_step": 1.0, "mujoco_single_us_per_step": 1.0,
         "ratio_reference_single_vs_mj_step": 1.0, "mujoco_adapter_single_us_per_step": 2.0,
         "drake_single_us_per_step": None, "drake_constant_force_us_per_step": None, "targets": {}}
    assert "Drake not installed (pip install 'rbcheck[drake]')" in bench.format_table(r)

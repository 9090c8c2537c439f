"""The scenario page states the second reference's verdict and its numbers from summary.json's record."""
from reports.html import _second_reference_text

REC = {"label": "drake 1.51.1 runge_kutta5, error-controlled, target accuracy 1e-13",
       "target_accuracy": 1e-13,
       "distance": {"position": 6.2e-14, "orientation": 3.9e-07,
                    "velocity": 0.0, "angular_velocity": 1.1e-06},
       "stated_accuracy": {"position": 1.5e-09, "orientation": 2.9e-06, "velocity": 3.2e-10,
                           "angular_velocity": 8.3e-06},
       "agrees": True}


def test_the_line_gives_the_verdict_and_every_distance_with_its_claim():
    line = _second_reference_text(REC)
    assert line.startswith(REC["label"] + ": agrees with the reference")
    assert "orientation 3.9e-7 rad (together they claim 2.9e-6 rad)" in line
    assert "velocity 0 m/s" in line


def test_a_disagreement_and_a_failure_are_said_so_and_no_record_no_line():
    assert "DISAGREES" in _second_reference_text({**REC, "agrees": False})
    assert _second_reference_text({**REC, "agrees": None,
                                   "error": "RuntimeError: x"}).endswith("failed (RuntimeError: x)")
    assert _second_reference_text(None) == ""

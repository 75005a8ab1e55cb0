"""Thesis section 5.10 validation and the library PID gains (docs/physics.md, pid-tuning.md)."""

import numpy as np
import pytest

from nearsub.common.analysis import validation as val
from nearsub.common.autonomy import pid_design
from nearsub.common.physics.vehicles import NPS_AUV_II, REMUS100, SDV, Gains


@pytest.fixture(scope="module")
def rows():
    return val.run_validation()


def test_every_validation_row_passes(rows):
    failed = [r for r in rows if not r.passed]
    assert not failed, val.format_table(failed)
    names = " ".join(r.name for r in rows)
    for vehicle in ("remus100", "nps_auv_ii", "sdv"):
        assert f"{vehicle} 90 deg heading step" in names
    assert val.format_table(rows).count("\n") == len(rows) + 1


def test_thesis_figures(rows):
    by_name = {r.name: r for r in rows}
    remus = by_name["REMUS 100 +4 deg rudder step, steady yaw rate"]
    assert remus.measured == pytest.approx(-10.04, rel=0.02)
    nps = by_name["NPS AUV II +/-15 deg every 45 s, yaw-rate amplitude"]
    assert nps.measured == pytest.approx(7.24, rel=0.03)
    m11 = by_name["REMUS 100 M11 = m - X_udot"]
    assert m11.measured == pytest.approx(31.41, abs=0.01) and m11.tolerance is None


@pytest.mark.parametrize(
    "vehicle, speed",
    [(REMUS100, 1.5), (NPS_AUV_II, 1.0), (SDV, 1.5)],
    ids=lambda v: getattr(v, "name", v),
)
def test_library_gains_follow_the_design_rule(vehicle, speed):
    heading = pid_design.design_heading_gains(vehicle, speed)
    speed_gains = pid_design.design_speed_gains(vehicle, speed)
    for designed, library in ((heading, vehicle.pid.heading), (speed_gains, vehicle.pid.speed)):
        for field in ("kp", "ki", "kd", "integral_limit"):
            assert getattr(library, field) == pytest.approx(getattr(designed, field), rel=0.05, abs=1e-12)


def test_incremental_form_cannot_stabilise_remus():
    """(5.21) with the derivative on the measurement gives no yaw-rate feedback: a heading-only
    loop (Kd = 0 in positional terms) leaves REMUS's open-loop instability unstable."""
    for kp in np.linspace(0.05, 5.0, 25):
        poles = pid_design.closed_loop_poles(REMUS100, 1.5, Gains(kp=kp))
        assert poles.real.max() > 0


def test_incremental_tuning_maps_gains_by_dt():
    tuning = pid_design.incremental_tuning(NPS_AUV_II, 1.0, 0.2, 0.05)
    assert (tuning.heading.kp, tuning.heading.kd, tuning.heading.ki) == pytest.approx((0.01, 0.05, 0.0))
    assert tuning.speed.kd == pytest.approx(NPS_AUV_II.pid.speed.kp * 0.05)

"""Covers bridge.nodes.vehicle.targets, bridge.nodes.vehicle.run and bridge.nodes.offboard.run: another profile.

``bsst vehicle`` and ``bsst controller`` started by hand with different ``--profile``s fly different actuation
modes (motors: HIL_ACTUATOR_CONTROLS; wrench: SET_ACTUATOR_CONTROL_TARGET): the vehicle refuses every target. It
says so once in words (a STATUSTEXT), the controller's failed end repeats what the vehicle warned, and the vehicle's
stderr says it with the count. Until the third wave's forty-second session both showed only a failsafe ("no new
state", "no actuator target") and a count, ``rejected 1: message 1``. Real processes on 127.0.0.1.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.nodes.report import Ready, parse_line
from bridge.session import instance_slot
from missions import MISSION_DIR
from tests.sitlkit import ENV, ROOT, Proc, run_bsst

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast


@pytest.mark.parametrize(("vehicle_profile", "controller_profile", "sent", "flown"), [
    ("x500", "paper", "SET_ACTUATOR_CONTROL_TARGET", "motors (HIL_ACTUATOR_CONTROLS)"),
    ("paper", "x500", "HIL_ACTUATOR_CONTROLS", "wrench (SET_ACTUATOR_CONTROL_TARGET)"),
])
def test_a_controller_of_another_profile_is_told_why_its_targets_are_refused(
        tmp_path: Path, vehicle_profile: str, controller_profile: str, sent: str, flown: str) -> None:
    mission = tmp_path / "short.toml"
    mission.write_text((MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 1.0"))
    said = (f"actuation: the controller sends {sent}; this vehicle (profile {vehicle_profile}) flies {flown}: "
            "refused; fly both with one --profile")
    with instance_slot() as n:
        vehicle = Proc.bsst("vehicle", "--profile", vehicle_profile, "--instance", str(n), "--gcs", "none", cwd=ROOT)
        try:
            vehicle.wait_line(lambda ln: isinstance(parse_line(ln), Ready), timeout=60)
            ctl = run_bsst("controller", str(mission), "--profile", controller_profile, "--instance", str(n),
                           cwd=ROOT, env=ENV, timeout=120)
        finally:
            code = vehicle.stop()
    assert ctl.returncode == 1, ctl.stderr
    lines = ctl.stderr.splitlines()
    assert f"bsst controller: the vehicle warned: {said}" in lines, lines
    assert lines.index(f"bsst controller: the vehicle warned: {said}") == 1, lines  # the first warning, after why
    assert code == 1  # its flight ended in its failsafe
    words = [ln for ln in vehicle.lines if ln.startswith(f"bsst vehicle: {said} (")]  # (its stderr: with stdout)
    assert len(words) == 1 and words[0].endswith(" refused)"), vehicle.lines[-5:]

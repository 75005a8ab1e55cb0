"""The launcher's lines for people (tools/launcher/status.py): a line for each change of what a
helm does, timestamped in simulated seconds, and the closest approaches in the summary."""

from nearsub.common.analysis.approach import Approaches, HullApproach, PairApproach
from nearsub.common.physics.hull import L_SUB
from nearsub.common.runtime.messages import HelmProgress, encode
from nearsub.tools.launcher.status import Console, Summary


class Stream:
    """What the launcher's lossy subscription hands over: (key, payload) pairs, then None."""

    def __init__(self, items):
        self.items = list(items)

    def try_recv(self):
        return self.items.pop(0) if self.items else None


def progress(t, mode="", active=("approach",), complete=False, behaviour="waypoints"):
    message = HelmProgress(
        step=round(t / 0.05), t=t, source="helm", behaviour=behaviour, leg=0, waypoint_index=0,
        waypoints_reached=0, psi_d=0.0, mode=mode, active=list(active), complete=complete,
    )  # fmt: skip
    return "nearsub/recovery/remus100/helm", encode(message)


def test_each_change_of_mode_behaviours_or_helm_is_one_line_and_nothing_else_is(capsys):
    console = Console(quiet=False)
    console.helm_phases(
        Stream(
            [
                progress(0.0, "RECOVERY:APPROACH"),
                progress(0.25, "RECOVERY:APPROACH"),  # no change: no line
                progress(96.0, "RECOVERY:HOLD", ("avoid_hull", "hold")),
                progress(150.0, "RECOVERY:HOLD", ("avoid_hull", "hold"), behaviour="nuv_compensation"),  # a swap
                progress(269.75, "RECOVERY:DEPART", (), complete=True, behaviour="nuv_compensation"),
            ]
        ),
        fleet=False,
    )
    lines = capsys.readouterr().err.splitlines()
    assert lines == [
        "  t=    0.00  phase      mode RECOVERY:APPROACH; active approach",
        "  t=   96.00  phase      mode RECOVERY:HOLD; active avoid_hull, hold",
        "  t=  150.00  phase      helm nuv_compensation",
        "  t=  269.75  phase      mode RECOVERY:DEPART; active none; complete",
    ]


def test_a_fleet_names_the_vehicle_and_json_output_prints_nothing(capsys):
    key, payload = progress(0.0)
    Console(quiet=False).helm_phases(Stream([(key.replace("remus100", "auv1"), payload)]), fleet=True)
    assert capsys.readouterr().err == "  t=    0.00  phase      auv1: active approach\n"
    Console(quiet=True).helm_phases(None, fleet=True)  # --json: no subscription at all
    assert capsys.readouterr().err == ""


def test_the_summary_gives_the_closest_approaches_in_text_and_json():
    summary = Summary("launch_two", "completed", steps=10, sim_time=0.5, startup_time=1.0)
    summary.approaches = Approaches(
        {"auv1": HullApproach(1.234, 12.5, -10.0)}, PairApproach(("auv1", "auv2"), 3.21, 40.0)
    )
    text = summary.text()
    assert "  auv1: closest to the hull 1.23 m at t=12.50 s, beside x=-10.0 m (R_long -0.113)" in text
    assert "  auv1 and auv2: closest 3.21 m apart at t=40.00 s" in text
    found = summary.as_dict()["approaches"]
    assert found["closest_pair"] == {"vehicles": ["auv1", "auv2"], "clearance_m": 3.21, "t": 40.0}
    assert found["hull"]["auv1"] == {"clearance_m": 1.234, "t": 12.5, "hull_x_m": -10.0, "r_long": -10.0 / L_SUB}

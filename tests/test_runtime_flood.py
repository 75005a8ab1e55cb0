"""A running mission against hostile traffic from a client on its router: a desired state from
the far future under the helm's name and a flood of 10,000 bad messages neither crash an app nor
stall the mission, and the trajectory is the in-process one, bit for bit."""

import re

import msgpack
import pytest

from conftest import ALPHA, nearsub
from helpers import finish, log_path, per_topic, wait_registered
from nearsub.common.mission.cores import build_cores
from nearsub.common.mission.schema import load_mission
from nearsub.common.runtime.bus import Bus, Endpoints
from nearsub.common.runtime.lifecycle import Schedule, run_inprocess
from nearsub.common.runtime.logfile import read_log
from nearsub.common.runtime.messages import Desired, encode

pytestmark = pytest.mark.timeout(300)

FLOOD = 10_000


def test_a_future_step_and_a_flood_do_not_stop_the_mission(launches, community):
    # Paused before step 100, so the flood arrives while the pid waits, whatever the load.
    process = launches.start(ALPHA, "--set", f"name={community}", "--set", "pause_at_step=100", "--until", "30")
    entry = wait_registered(community)
    key = f"nearsub/{community}/remus100/desired"
    with Bus(Endpoints("client", tuple(entry["connect"]), credentials=entry["credentials"])) as bus:
        future = Desired(step=10**9, t=0.0, source="helm", u_d=1.0, psi_d=0.0)
        assert bus.put_when_matched(key, encode(future), wait=30.0)
        wrong_source = encode(Desired(step=100, t=5.0, source="intruder", u_d=1.0, psi_d=0.0))
        bad_fields = msgpack.packb({"step": 100, "t": 5.0, "source": "helm", "u_d": "fast"})
        for i in range(FLOOD):
            bus.put(key, (wrong_source, bad_fields, b"\xc1")[i % 3])
    assert nearsub("clock", community, "resume").returncode == 0
    code, summary, err = finish(process)
    assert code == 0 and summary["outcome"] == "time_limit", err

    mission = load_mission(ALPHA, [f"name={community}", "time_limit=30"])
    reference = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    logged = per_topic(log_path(summary))
    for leaf in ("state", "input"):
        assert logged[f"remus100/{leaf}"] == [encode(m) for m in reference.topic(leaf)], leaf
    records = read_log(log_path(summary)).records
    errors = [
        r.value()["detail"] for r in records if r.topic.endswith("/events/pid-1") and r.value()["kind"] == "error"
    ]
    assert "desired with step 1000000000 ignored" in errors[0]
    assert len(errors) < 60  # rate-limited: about one a second
    counted = sum(int(n) for e in errors for n in re.findall(r"and (\d+) more errors", e))
    reported = sum(not e.startswith("mission over") for e in errors)
    assert reported + counted == 1 + FLOOD

"""The logger logs control requests and operator overrides, which are sent with t = 0, at the
simulated time the mission had reached when they arrived, and every other message at its own t."""

from nearsub.apps.logger import Recorder
from nearsub.common.runtime.messages import Control, Desired, State, encode


class Writer:
    def __init__(self):
        self.rows = []

    def write(self, key, data, sim_time, valid=True):
        self.rows.append((key, sim_time, valid))


def state(step: int) -> State:
    return State(step=step, t=step * 0.05, source="sim-1", u=1.0, v=0.0, r=0.0, x=0.0, y=0.0, psi=0.0)


def control(cmd: str) -> Control:
    return Control(step=0, t=0.0, source="tool-1", cmd=cmd, request_id=cmd, reply_to="tool-1")


def test_requests_are_logged_when_they_arrive_not_at_zero():
    writer = Writer()
    recorder = Recorder(writer, "alpha")
    recorder.record("nearsub/alpha/control/clock", encode(control("status")))  # before any step
    for step in range(101):
        recorder.record("nearsub/alpha/remus100/state", encode(state(step)))
    recorder.record("nearsub/alpha/control/clock", encode(control("pause")))
    override = Desired(step=0, t=0.0, source="operator", u_d=1.0, psi_d=0.0)
    recorder.record("nearsub/alpha/remus100/desired", encode(override))
    recorder.record("nearsub/alpha/remus100/state", encode(state(101)))
    recorder.record("nearsub/alpha/control/clock", encode(control("resume")))
    recorder.record("nearsub/alpha/launcher/control", b"\x80")  # no model: at the time reached too
    helm = Desired(step=100, t=5.0, source="helm-1", u_d=1.0, psi_d=0.0)
    recorder.record("nearsub/alpha/remus100/desired", encode(helm))
    times = [(key.rsplit("/", 1)[-1], t) for key, t, _ in writer.rows if not key.endswith("state")]
    assert times == [("clock", 0.0), ("clock", 5.0), ("desired", 5.0), ("clock", 101 * 0.05), ("control", 101 * 0.05),
                     ("desired", 5.0)]  # fmt: skip

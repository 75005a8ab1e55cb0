"""The mission end loses nothing of the last step: the sim's follow-up work (its forces at the
final state, `Iteration.then`) still reaches the surrogate server and the log after the clock has
ended the mission."""

from types import SimpleNamespace

from nearsub.apps.logger import Recorder
from nearsub.common.runtime import keys
from nearsub.common.runtime.messages import AppStatus, MissionEnd, encode
from nearsub.tools.launcher import processes


class Writer:
    def write(self, key, data, sim_time, valid=True):
        pass


def status(instance: str, state: str) -> bytes:
    app = instance.rsplit("-", 1)[0]
    return encode(AppStatus(step=0, t=0.0, source=app, app=app, instance=instance, state=state))


def test_the_logger_knows_which_apps_have_not_yet_said_stopping():
    recorder = Recorder(Writer(), "alpha")
    for instance in ("helm-1", "pid-1", "sim-1"):
        recorder.record(f"nearsub/alpha/status/{instance}", status(instance, "running"))
    recorder.record("nearsub/alpha/status/helm-2", status("helm-2", "running"))  # a swap
    recorder.record("nearsub/alpha/status/helm-1", status("helm-1", "stopping"))
    end = MissionEnd(step=10, t=0.5, source="clock", outcome="completed", reason="done")
    recorder.record("nearsub/alpha/clock/end", encode(end))

    def alive(instance: str) -> str:  # the app's liveliness token, which goes away when it dies
        return keys.alive("alpha", instance.rsplit("-", 1)[0], instance)

    assert recorder.end is not None and recorder.running == {alive("helm-2"), alive("pid-1"), alive("sim-1")}
    for instance in ("helm-2", "pid-1"):
        recorder.record(f"nearsub/alpha/status/{instance}", status(instance, "stopping"))
    assert recorder.running == {alive("sim-1")}  # the logger records until the sim has left (or died)


def test_the_surrogate_server_is_stopped_after_the_apps_that_ask_it(monkeypatch):
    order = []
    monkeypatch.setattr(processes, "stop", lambda stopped, grace=0.0: order.extend(p for p in stopped))
    roles = ("logger", "surrogate", "clock", "helm", "pid", "sim")
    children = {role: SimpleNamespace(role=role, process=role) for role in roles}
    owner = SimpleNamespace(children=children, companions=[], router_lost=lambda: False)
    processes.Processes.stop_all(owner)
    assert order.index("surrogate") > max(order.index(role) for role in ("clock", "helm", "pid", "sim"))
    assert order[-1] == "logger"

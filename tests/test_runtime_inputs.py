"""A lock-stepped app's shell over a real Zenoh router, fed by hand: it receives exactly its
declared inputs, the clock's traffic and its own control keys, and no message, however bad or
however many, stops it or changes what it computes."""

import re
import threading
from collections import Counter

import pytest
from test_fleet import TWO

from conftest import ALPHA
from helpers import wait_until
from nearsub.apps.shell import AppShell
from nearsub.common.mission.cores import HelmCore, PidCore, build_cores, run_mission
from nearsub.common.mission.schema import RunConfig, load_mission
from nearsub.common.runtime import keys
from nearsub.common.runtime.bus import Bus, Endpoints, free_tcp_port, make_config
from nearsub.common.runtime.lifecycle import Schedule, run_inprocess
from nearsub.common.runtime.messages import (
    Ack,
    Desired,
    Event,
    Input,
    MissionEnd,
    Tick,
    decode,
    encode,
)

pytestmark = pytest.mark.timeout(180)


class CountingShell(AppShell):
    """The pid's shell, counting every sample its stream hands it, by key."""

    received: Counter

    def loop(self) -> int:
        self.received = Counter()
        stream = self.stream

        class Counting:
            def recv(_):
                key, payload = stream.recv()
                self.received[key] += 1
                return key, payload

        self.stream = Counting()
        return super().loop()


def test_pid_shell_receives_only_its_inputs_and_survives_bad_and_future_messages():
    mission = load_mission(ALPHA, ["name=inputs-test", "time_limit=5"])
    c, vehicle = mission.name, mission.vehicle_name
    reference = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    states, desireds = reference.topic("state"), reference.topic("desired")
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    with Bus(make_config("router", listen=[endpoint])), Bus(Endpoints("client", (endpoint,))) as world:
        outputs, events = [], []
        world.session.declare_subscriber(keys.vehicle_topic(c, vehicle, "input"), lambda s: outputs.append(s))
        world.session.declare_subscriber(keys.all_events(c), lambda s: events.append(s))
        shell = CountingShell(lambda m, s: PidCore(m), RunConfig(mission=mission, connect=[endpoint]), "pid-1")
        thread = threading.Thread(target=shell.serve, daemon=True)
        thread.start()
        wait_until(lambda: world.alive(keys.alive(c, "pid", "*")), mission.startup_timeout, "the pid did not start")

        key = {leaf: keys.vehicle_topic(c, vehicle, leaf) for leaf in ("state", "desired", "input", "helm")}
        sent = Counter()

        def put(k: str, payload: bytes) -> None:
            if not sent[k]:
                world.put_when_matched(k, payload, wait=mission.startup_timeout)
            else:
                world.put(k, payload)
            sent[k] += 1

        # Traffic the pid does not consume: other topics, other apps' control keys, events, status.
        noise = {
            key["input"]: encode(Input(step=0, t=0.0, source="pid", X_prop=1.0, delta_r=0.0)),
            key["helm"]: b"\x80",
            keys.control(c, "helm-1"): b"\x80",
            keys.events(c, "someone"): encode(Event(step=0, t=0.0, source="x", kind="info")),
            keys.status(c, "someone"): b"\x80",
        }
        for k, payload in noise.items():
            world.put(k, payload)
        # A desired state from the far future, with the helm's name, then a flood of bad ones.
        future = Desired(step=10**9, t=0.0, source="helm", u_d=1.0, psi_d=0.0)
        put(key["desired"], encode(future))
        bad = 1 + 3000
        for i in range(bad - 1):
            put(key["desired"], b"\xc1" if i % 2 else encode(Desired(step=0, t=0.0, source="tap", u_d=1.0, psi_d=0.0)))
        desired = iter(desireds)
        for state in states[:-1]:  # the last state is the sim's x_N, which no pid step reads
            if state.step % mission.periods()["helm"] == 0:
                put(key["desired"], encode(next(desired)))
            put(key["state"], encode(state))
            # The clock's grant of the step (it never grants further ahead than its window).
            put(keys.tick(c), encode(Tick(step=state.step, t=0.0, source="clock")))
            for k, payload in noise.items():
                world.put(k, payload)

        expected = reference.topic("input")
        timeout = mission.startup_timeout + mission.step_timeout
        wait_until(lambda: len(outputs) >= len(expected) + len(states), timeout, "the pid did not publish every input")
        put(keys.mission_end(c), encode(MissionEnd(step=mission.max_steps, t=0.0, source="clock", outcome="x")))
        thread.join(timeout)
        assert not thread.is_alive()
        wait_until(lambda: rejections(events) == bad, timeout, f"not all {bad} rejections were reported")

    published = [s.payload.to_bytes() for s in outputs]
    assert [p for p in published if p != noise[key["input"]]] == [encode(m) for m in expected]
    # It received exactly what was sent on its inputs, the clock's keys and nothing else.
    assert shell.received == sent
    assert set(sent) == {key["state"], key["desired"], keys.tick(c), keys.mission_end(c)}
    # Every rejection is reported, in a few rate-limited events that count the rest.
    errors = pid_errors(events)
    assert "desired with step 1000000000 ignored" in errors[0].detail
    assert len(errors) < 10


def pid_errors(samples) -> list[Event]:
    events = [decode(s.payload.to_bytes(), Event) for s in list(samples)]
    return [e for e in events if e.kind == "error" and e.source == "pid"]


def rejections(samples) -> int:
    """Rejections reported: one per error event, plus the ones each event counts ("mission over"
    only counts)."""
    total = 0
    for event in pid_errors(samples):
        total += 0 if event.detail.startswith("mission over") else 1
        total += sum(int(n) for n in re.findall(r"and (\d+) more errors", event.detail))
    return total


def test_a_fleet_vehicles_pid_receives_only_its_own_vehicles_inputs():
    """In a mission of two vehicles, auv2's pid hears auv2's state and desired, the clock's ticks
    and end, and nothing of auv1 (its data, acks, control keys) nor of the other acks."""
    mission = load_mission(TWO, ["name=fleet-inputs-test", "time_limit=5"])
    c = mission.name
    reference = run_mission(mission)
    states, desireds = reference.topic("state", "auv2"), reference.topic("desired", "auv2")
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    with Bus(make_config("router", listen=[endpoint])), Bus(Endpoints("client", (endpoint,))) as world:
        outputs = []
        world.session.declare_subscriber(keys.vehicle_topic(c, "auv2", "input"), lambda s: outputs.append(s))
        run = RunConfig(mission=mission, connect=[endpoint])
        shell = CountingShell(lambda m, s: PidCore(m), run, "auv2/pid-1", "auv2")
        thread = threading.Thread(target=shell.serve, daemon=True)
        thread.start()
        timeout = mission.startup_timeout + mission.step_timeout
        wait_until(lambda: world.alive(keys.alive(c, "auv2/pid", "*")), timeout, "auv2's pid did not start")
        own = {leaf: keys.vehicle_topic(c, "auv2", leaf) for leaf in ("state", "desired")}
        others = {
            keys.vehicle_topic(c, "auv1", "state"): encode(reference.topic("state", "auv1")[0]),
            keys.vehicle_topic(c, "auv1", "desired"): encode(reference.topic("desired", "auv1")[0]),
            keys.ack(c, "auv1/pid"): encode(Ack(step=0, t=0.0, source="pid", end="completed")),
            keys.ack(c, "auv2/helm"): encode(Ack(step=0, t=0.0, source="helm")),
            keys.control(c, "auv1/pid-1"): b"\x80",
            keys.vehicle_topic(c, "auv1", "input"): b"\x80",
        }
        sent = Counter()

        def put(k: str, payload: bytes) -> None:
            world.put_when_matched(k, payload, wait=timeout) if not sent[k] else world.put(k, payload)
            sent[k] += 1

        desired = iter(desireds)
        for state in states[:-1]:
            for k, payload in others.items():
                world.put(k, payload)
            if state.step % mission.members()[1].periods()["helm"] == 0:
                put(own["desired"], encode(next(desired)))
            put(own["state"], encode(state))
            put(keys.tick(c), encode(Tick(step=state.step, t=0.0, source="clock")))  # a fleet's window: 1
        expected = reference.topic("input", "auv2")
        wait_until(lambda: len(outputs) >= len(expected), timeout, "auv2's pid did not publish every input")
        put(keys.mission_end(c), encode(MissionEnd(step=mission.max_steps, t=0.0, source="clock", outcome="x")))
        thread.join(timeout)
        assert not thread.is_alive()
    assert [s.payload.to_bytes() for s in outputs] == [encode(m) for m in expected]
    assert shell.received == sent
    assert set(sent) == {own["state"], own["desired"], keys.tick(c), keys.mission_end(c)}


def test_the_helm_wakes_only_for_the_states_of_its_own_steps():
    """The helm (period 5) reads every 5th state: it subscribes to the state's feed, which the sim
    fills at the helm's steps, and never hears the states between them."""
    mission = load_mission(ALPHA, ["name=helm-inputs-test", "time_limit=5"])
    c, vehicle = mission.name, mission.vehicle_name
    period = mission.periods()["helm"]
    assert period > 1
    reference = run_inprocess(build_cores(mission), Schedule(mission.periods()), mission.dt, mission.max_steps)
    states = reference.topic("state")
    plain, feed = keys.vehicle_topic(c, vehicle, "state"), keys.feed(c, vehicle, "state", period)
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    with Bus(make_config("router", listen=[endpoint])), Bus(Endpoints("client", (endpoint,))) as world:
        outputs = []
        world.session.declare_subscriber(keys.vehicle_topic(c, vehicle, "desired"), lambda s: outputs.append(s))
        shell = CountingShell(lambda m, s: HelmCore(m), RunConfig(mission=mission, connect=[endpoint]), "helm-1")
        thread = threading.Thread(target=shell.serve, daemon=True)
        thread.start()
        timeout = mission.startup_timeout + mission.step_timeout
        wait_until(lambda: world.alive(keys.alive(c, "helm", "*")), timeout, "the helm did not start")
        sent = Counter()

        def put(k: str, payload: bytes) -> None:
            world.put_when_matched(k, payload, wait=timeout) if not sent[k] else world.put(k, payload)
            sent[k] += 1

        for state in states[:-1]:  # as the sim's shell publishes them, each step granted as the clock does
            world.put(plain, encode(state))
            if state.step % period == 0:
                put(feed, encode(state))
            put(keys.tick(c), encode(Tick(step=state.step, t=0.0, source="clock")))
        expected = reference.topic("desired")
        wait_until(lambda: len(outputs) >= len(expected), timeout, "the helm did not publish every desired state")
        put(keys.mission_end(c), encode(MissionEnd(step=mission.max_steps, t=0.0, source="clock", outcome="x")))
        thread.join(timeout)
        assert not thread.is_alive()
    assert [s.payload.to_bytes() for s in outputs] == [encode(m) for m in expected]
    assert shell.received == sent and sent[feed] == len(expected) == -(-(len(states) - 1) // period)
    assert plain not in shell.received

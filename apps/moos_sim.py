"""`nearsub moos sim`: nearsub's sim as a MOOS app, a uSimMarineV22 replacement in the user's
MOOS community (docs/moos.md). The MOOSDB client is pymoos2's (the `moos` extra); the sim itself is
`common.moos.sim.MoosSim`, which runs the mission's own `SimCore`.

Every AppTick (in MOOS time, so MOOSTimeWarp speeds it up) it reads the DESIRED_* mail, runs the
steps MOOS time has made due, and posts NAV_*, the NEARSUB_* forces and events, the submarine's
NODE_REPORT and its hull's VIEW_SEGLIST; it posts an APPCAST every few seconds of MOOS time and on request.
The MOOSDB going away ends it with one line and exit 1: MOOS's C++ apps reconnect, but a vehicle
whose actuators were unheard meanwhile would jump ahead on reconnection, so the sim stops and
its process watcher (uProcessWatch) reports it gone."""

from __future__ import annotations

import time

from nearsub.apps.entry import AppError
from nearsub.common.moos import bridge
from nearsub.common.moos.config import SimConfig
from nearsub.common.moos.sim import MoosSim

CONNECT_TIMEOUT = 10.0  # wall seconds to reach the MOOSDB at start-up
APPCAST_PERIOD = 2.0  # MOOS seconds between AppCasts (uMAC asks for them again every few seconds)


def run(config: SimConfig, mission, name: str, surrogate=None) -> int:
    from pymoos2.core import time as moos_clock
    from pymoos2.core.MOOSCommClient import MOOSCommClient

    moos_clock.set_moos_time_warp(config.time_warp)
    client = MOOSCommClient(config.host, config.port, app_name=name, comm_tick=config.comms_tick)
    for variable in (*bridge.ACTUATOR_VARIABLES, "APPCAST_REQ"):
        client.register(variable)
    client.start()
    try:
        if not client.wait_until_connected(CONNECT_TIMEOUT):
            raise AppError(f"no MOOSDB at {config.host}:{config.port} after {CONNECT_TIMEOUT:g} s", 1)
        return loop(client, MoosSim(mission, config, moos_clock.moos_time(), surrogate), config, name)
    finally:
        client.stop()


def loop(client, sim: MoosSim, config: SimConfig, name: str) -> int:
    from pymoos2.core import time as moos_clock

    post(client, sim.report())
    iteration, elapsed, next_appcast, tick = 0, 1e-9, 0.0, 1.0 / config.app_tick
    wall_start = time.monotonic()
    while True:
        if not client.is_connected:
            raise AppError(
                f"lost the MOOSDB at {config.host}:{config.port} at sim time {sim.state.t:.2f} s; exiting", 1
            )
        for message in client.fetch():
            if message.key == "APPCAST_REQ":
                next_appcast = 0.0
            else:
                sim.receive(message.key, message.val if message.is_double() else message.string())
        now = moos_clock.moos_time()
        post(client, sim.advance(now))
        if sim.end is None:  # the rates are those of the stepping, not of the idling after its end
            iteration, elapsed = iteration + 1, max(time.monotonic() - wall_start, 1e-9)
        if now >= next_appcast:
            achieved = iteration / (elapsed * config.time_warp)  # per second of MOOS time
            status = sim.status() | {
                "behind MOOS time": f"{sim.lag(now):.2f} s",
                "AppTick asked, achieved": f"{config.app_tick:g}, {achieved:.1f}",
                "steps per wall second": f"{sim.steps / elapsed:.0f}",
            }
            warnings = {f"malformed {key} ignored": count for key, count in sim.actuators.malformed.items()}
            appcast = bridge.appcast(name, config.community, iteration, status, sim.events, warnings)
            client.notify("APPCAST", appcast)
            next_appcast = now + APPCAST_PERIOD
        moos_clock.moos_pause(max(0.0, now + tick - moos_clock.moos_time()) * 1000.0)  # the rest of the tick


def post(client, posts) -> None:
    for key, value in posts:
        client.notify(key, value)


def missing_client() -> str | None:
    """The line to print when the MOOS client is not installed, else None."""
    import importlib.util

    if importlib.util.find_spec("pymoos2") is None:
        return "MOOS support needs its extra: pip install 'nearsub[moos]'"
    return None

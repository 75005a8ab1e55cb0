"""nearsub's sim as a MOOS app, without the MOOS client: DESIRED_* mail and MOOS time in, the
variables to post out. It runs the mission's own `SimCore` (`mission.cores`) as a mission does:
the same dynamics, the interaction in the mission's mode (increment by default) with the LF in
this process and the residual from the mission's surrogate model, the same proximity events.
The community's pHelmIvP and pMarinePID replace nearsub's helm and pid (docs/moos.md)."""

from __future__ import annotations

from nearsub.common.mission import cores
from nearsub.common.mission.schema import Mission, apply_overrides, load_mission, mission_from_dict
from nearsub.common.moos import bridge
from nearsub.common.moos.config import SimConfig
from nearsub.common.physics import hull
from nearsub.common.runtime.messages import Input

# The mission a .moos block without `mission =` flies: REMUS 100, no submarine, a day's limit.
# The schema asks for a helm; the community's pHelmIvP is the helm, so this one never runs.
BASE_MISSION = {
    "name": "moos",
    "time_limit": 86400.0,
    "environment": {"submarine": False},
    "apps": {"helm": {"legs": [{"points": [[0.0, 0.0]], "speed": 1.0}]}},
}


def sim_mission(config: SimConfig) -> Mission:
    """The mission the block describes: its `mission` file (or BASE_MISSION), its keys and
    start_pos on top (MissionError names a bad value)."""
    overrides = list(config.overrides)
    if config.start:
        x0, y0 = config.submarine_pos
        start = config.start
        if "x" in start:
            overrides.append(f"start.x={start['x'] - x0}")
        if "y" in start:
            overrides.append(f"start.y={start['y'] - y0}")
        if "heading" in start:
            overrides.append(f"start.psi_deg={(90.0 - start['heading'] + 180.0) % 360.0 - 180.0}")
        if "speed" in start:
            overrides.append(f"start.speed={start['speed']}")
    if config.mission:
        return load_mission(config.mission, overrides)
    data = apply_overrides(_copy(BASE_MISSION), overrides)
    return mission_from_dict(data, "the nearsub_sim block", overrides)


def _copy(data):
    return {k: _copy(v) for k, v in data.items()} if isinstance(data, dict) else data


class MoosSim:
    """One vehicle's SimCore driven by MOOS time: `receive` the DESIRED_* mail, `advance` to the
    MOOS time now, and post what it returns."""

    def __init__(self, mission: Mission, config: SimConfig, t0: float, surrogate=None):
        self.core = cores.SimCore(mission, surrogate)
        self.vehicle = mission.vehicle_model
        self.prefix, self.datum = config.prefix, config.datum
        self.period = mission.apps.sim.period
        self.clock = bridge.MoosClock(t0, mission.dt * self.period)
        self.submarine = mission.environment.submarine
        self.placement = bridge.Placement(config.submarine_pos, mission.environment.u_sub)
        self.outline = hull.submarine_outline(bridge.HULL_STATIONS) if self.submarine else None
        self.actuators = bridge.Actuators()
        self.steps = 0  # sim steps run (each `period` base steps)
        self.events: list[str] = []
        self.end: str | None = None
        self.state, self.forces = None, None
        for leaf, message in self.core.startup():
            self.take(leaf, message)

    def take(self, leaf: str, message) -> None:
        if leaf == "state":
            self.state = message
        elif leaf == "forces":
            self.forces = message

    def receive(self, name: str, value) -> None:
        if name in bridge.ACTUATOR_VARIABLES:
            self.actuators.receive(name, value)

    def advance(self, moos_now: float) -> list[tuple[str, object]]:
        """Run the steps due by `moos_now` with the latest actuators; the variables to post
        (nothing new when no step was due, or after the mission ended)."""
        if self.end is not None:
            return []
        posts: list[tuple[str, object]] = []
        due = self.clock.due(moos_now, self.steps)
        for _ in range(due):
            base_step = self.steps * self.period
            t = self.state.t
            thrust, rudder = self.actuators.command(self.vehicle)
            self.core.new_mail({"input": Input(step=base_step, t=t, source="moos", X_prop=thrust, delta_r=rudder)})
            result = self.core.iterate(base_step, t)
            self.steps += 1
            for leaf, message in result.outputs:
                self.take(leaf, message)
            if result.then is not None:
                for leaf, message in result.then().outputs:
                    self.take(leaf, message)
            for found in result.events:
                self.events.append(f"t={found.t:.2f} {found.kind}: {found.detail}")
                posts += bridge.event_variables(found.kind, found.detail).items()
            if result.end is not None:
                self.end = result.reason
                posts.append(("NEARSUB_END", result.reason))
                break
        return posts + self.report() if due else posts

    def report(self) -> list[tuple[str, object]]:
        """NAV_*, the NEARSUB_* forces, and the submarine's NODE_REPORT and hull."""
        t = self.state.t
        posts = list(bridge.nav_variables(self.state, t, self.placement, self.datum, self.prefix).items())
        if self.forces is not None:
            posts += bridge.forces_variables(self.forces).items()
        if self.submarine:
            moos_time = self.clock.t0 + t
            posts.append(("NODE_REPORT", bridge.submarine_report(t, moos_time, self.placement)))
            posts.append(("VIEW_SEGLIST", bridge.hull_seglist(*self.outline, t, self.placement)))
        return posts

    def lag(self, moos_now: float) -> float:
        """How far the state is behind MOOS time [s]: below one step while the CPU keeps up with
        the warp (0 once the stepping has ended)."""
        return 0.0 if self.end is not None else max(0.0, moos_now - self.clock.t0 - self.state.t)

    def status(self) -> dict:
        s, f = self.state, self.forces
        return {
            "MOOS time of the state": f"{self.clock.t0 + s.t:.2f}",
            "sim time": f"{s.t:.2f} s ({self.steps} steps)",
            "vehicle": self.vehicle.name,
            "heading, speed": f"{bridge.compass_heading(s.psi):.1f} deg, {s.u:.2f} m/s",
            "thrust, rudder": f"{self.actuators.thrust:g} %, {self.actuators.rudder:g} deg",
            "interaction": "off" if f is None else f"N_s = {f.N_s:.3g} N m, in domain {f.in_domain}",
            "ended": self.end or "no",
        }

"""A running nearsub mission as pMarineViewer sees a MOOS community (`nearsub moos watch`): each
vehicle's state as its NODE_REPORT, the submarine and its hull, each vehicle's waypoints as
VIEW_POINTs and its track as a VIEW_SEGLIST, and the events as NEARSUB_* variables. Positions are
on the MOOS grid of docs/moos.md: the submarine's CB at the origin at t = 0, heading east at
U_sub, so the waypoints, fixed in the submarine's frame, move with it. A vehicle's NODE_REPORT is
posted at most every REPORT_INTERVAL of simulated time (pNodeReporter's rate, not every step), and
stamped with the poster's MOOS time (`clock`), as pMarineViewer judges staleness by it."""

from __future__ import annotations

import time

from nearsub.common.moos import bridge
from nearsub.common.physics import hull

REPORT_INTERVAL = 0.25  # simulated seconds between a vehicle's NODE_REPORTs (pNodeReporter's 4 Hz)


class MissionWatch:
    def __init__(self, mission, clock=time.time):
        self.members = {member.vehicle_name: member for member in mission.members()}
        self.submarine = mission.environment.submarine
        self.placement = bridge.Placement((0.0, 0.0), mission.environment.u_sub)
        self.outline = hull.submarine_outline(bridge.HULL_STATIONS) if self.submarine else None
        self.t = 0.0
        self.clock = clock
        self.reported: dict[str, float] = {}  # vehicle -> sim time of its last NODE_REPORT

    def translate(self, key: str, fields: dict) -> list[tuple[str, object]]:
        """The MOOS posts of one message on `nearsub/<community>/<chunk>/<leaf>` (decoded)."""
        parts = key.split("/")
        if len(parts) < 4:
            return []
        chunk, leaf = parts[2], parts[3]
        self.t = max(self.t, float(fields.get("t", 0.0) or 0.0))
        if leaf == "state" and len(parts) == 4 and chunk in self.members:
            t = float(fields["t"])
            if t < self.reported.get(chunk, -REPORT_INTERVAL) + REPORT_INTERVAL - 1e-9:
                return []
            self.reported[chunk] = t
            return [("NODE_REPORT", self.vehicle_report(chunk, fields))]
        if chunk == "events" and "kind" in fields:
            return list(bridge.event_variables(fields["kind"], fields.get("detail", "")).items())
        return []

    def vehicle_report(self, name: str, state: dict) -> str:
        t = float(state["t"])
        x, y = self.placement.to_moos(float(state["x"]), float(state["y"]), t)
        heading = bridge.compass_heading(float(state["psi"]))
        length = self.members[name].vehicle_model.length
        return bridge.node_report(name, x, y, heading, float(state["u"]), self.clock(), "uuv", length, "yellow")

    def scene(self) -> list[tuple[str, object]]:
        """What moves with the submarine, at the latest time seen: the submarine, its hull, and
        every vehicle's waypoints and track (posted again every few seconds)."""
        t, posts = self.t, []
        if self.submarine:
            posts.append(("NODE_REPORT", bridge.submarine_report(t, self.clock(), self.placement)))
            posts.append(("VIEW_SEGLIST", bridge.hull_seglist(*self.outline, t, self.placement)))
        for name, member in self.members.items():
            track = [(member.start.x, member.start.y)]
            for leg in member.apps.helm.legs:
                track += [(float(px), float(py)) for px, py in leg.points]
            placed = [self.placement.to_moos(px, py, t) for px, py in track]
            for index, (px, py) in enumerate(placed[1:], start=1):
                posts.append(("VIEW_POINT", f"x={px:.2f},y={py:.2f},label={name}_wpt{index},vertex_size=4"))
            points = ":".join(f"{px:.2f},{py:.2f}" for px, py in placed)
            posts.append(("VIEW_SEGLIST", f"pts={{{points}}},label={name}_track,edge_color=white"))
        return posts

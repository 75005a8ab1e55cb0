"""`nearsub log plot LOG`: the trajectory in the mission's frame and the time series of a mission.

The left panel shows the submarine outline (when the mission has one), the waypoints and
track-lines from the mission in the log, the UUV path and where events happened. The right
panels show desired and actual heading and speed, the rudder and thrust, and the interaction
forces when the log has them. This is how the thesis figures 5-5, 6-2, 6-3 and 6-6 are drawn.
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from nearsub.common.mission.schema import mission_from_dict  # noqa: E402
from nearsub.common.physics.hull import submarine_outline  # noqa: E402
from nearsub.common.runtime.keys import vehicle_of  # noqa: E402
from nearsub.common.runtime.logfile import read_log  # noqa: E402
from nearsub.common.viewer.scene import frame_description, mission_legs  # noqa: E402

EVENT_STYLE = {  # marker, colour, z-order: a waypoint reached on top of the stray its new leg starts with
    "collision": ("X", "red", 5),
    "close_call": ("o", "orange", 4),
    "large_stray": ("^", "purple", 3),
    "waypoint": ("*", "green", 4),
}


def series(records, leaf: str) -> dict[str, np.ndarray]:
    """Columns of one vehicle topic, keyed by field name."""
    columns = defaultdict(list)
    for record in records:
        if record.topic.endswith(f"/{leaf}") and "#" not in record.topic:
            for name, value in record.value().items():
                if isinstance(value, (int, float)) and not isinstance(value, bool):
                    columns[name].append(value)
    return {name: np.asarray(values) for name, values in columns.items()}


def by_vehicle(records) -> dict[str, list]:
    """The records of each vehicle named in the keys, vehicles sorted by name."""
    grouped = defaultdict(list)
    for record in records:
        owner = vehicle_of(record.topic)
        if owner is not None:
            grouped[owner[0]].append(record)
    return dict(sorted(grouped.items()))


def _degrees(values):
    return None if values is None else np.degrees(values)


def _same_turn(t_desired, psi_desired, t, heading_deg):
    """Desired heading [deg] shifted by whole turns to lie within 180 deg of the actual heading
    at the same time, so that a UUV circling the octagon does not draw 360 deg jumps."""
    if t_desired is None:
        return None
    actual = np.interp(t_desired, t, heading_deg)
    desired = np.degrees(psi_desired)
    return desired + 360.0 * np.round((actual - desired) / 360.0)


def draw_plan(ax, mission, tracks: list[tuple[str, str, dict[str, np.ndarray]]], events: list[dict]) -> None:
    """The plan view in the submarine frame: hull outline, track-lines and waypoints, each
    vehicle's path (label, colour, state columns) and the events that carry a position."""
    if mission is None or mission.environment.submarine:
        sx, sy = submarine_outline()
        ax.fill(sx, sy, color="0.8", label="submarine")
    legs = [] if mission is None else [leg for member in mission.members() for leg in mission_legs(member)]
    for number, leg in enumerate(legs):
        points, track = np.array(leg["points"]), np.array(leg["track"])
        ax.plot(track[:, 0], track[:, 1], "b--", lw=1, label=None if number else "track-lines")
        ax.plot(points[:, 0], points[:, 1], "bs", ms=5, label=None if number else "waypoints")
    for label, colour, state in tracks:
        ax.plot(state["x"], state["y"], "-", color=colour, lw=1.5, label=label)
    marked = set()
    for event in events:
        kind = event.get("kind")
        style = EVENT_STYLE.get(kind)
        if style and "x" in event.get("data", {}):
            label = None if kind in marked else kind.replace("_", " ")  # each kind once in the legend
            marked.add(kind)
            ax.plot(
                event["data"]["x"], event["data"]["y"], style[0], color=style[1], ms=9, label=label, zorder=style[2]
            )
    ax.set_xlabel(f"x [m]; {frame_description(mission)}")
    ax.set_ylabel("y [m]")


def plot_log(path: str | Path, output: str | Path | None = None, title: str | None = None) -> Path:
    """Draw a log: one track (own colour, labelled with its name) and one set of time series per
    vehicle; a single vehicle keeps the look of one UUV (a red track labelled "UUV")."""
    contents = read_log(path)
    resolved = contents.metadata.get("mission", {}).get("resolved")
    mission = mission_from_dict(json.loads(resolved)) if resolved else None
    vehicles = {
        name: {leaf: series(records, leaf) for leaf in ("state", "desired", "input", "forces")}
        for name, records in by_vehicle(contents.records).items()
    }
    vehicles = {name: data for name, data in vehicles.items() if data["state"]}
    if not vehicles:
        raise ValueError(f"{path}: no state messages to plot")
    single = len(vehicles) == 1
    colours = {name: ("red" if single else f"C{i % 10}") for i, name in enumerate(vehicles)}
    tracks = [("UUV" if single else name, colours[name], data["state"]) for name, data in vehicles.items()]

    fig = plt.figure(figsize=(15, 10), constrained_layout=True)
    grid = fig.add_gridspec(5, 2, width_ratios=[1.2, 1])
    overview = fig.add_subplot(grid[:3, 0])
    close_up = fig.add_subplot(grid[3:, 0])
    events = [r.value() for r in contents.records if "/events/" in r.topic and "#" not in r.topic]
    for ax in (overview, close_up):
        draw_plan(ax, mission, tracks, events)
    overview.set_aspect("equal", adjustable="datalim")
    overview.legend(loc="best", fontsize=8)
    outcome = contents.metadata.get("outcome", {})
    overview.set_title(title or f"{Path(path).stem}: {outcome.get('outcome', '?')}")
    # The close-up frames the UUVs' paths at free aspect: beside an 89 m hull, deviations of a
    # few decimetres are what decides a collision, and they vanish at equal scales.
    for axis, name in ((close_up.set_xlim, "x"), (close_up.set_ylim, "y")):
        values = np.concatenate([data["state"][name] for data in vehicles.values()])
        margin = max(0.1 * np.ptp(values), 1.0)
        axis(values.min() - margin, values.max() + margin)
    close_up.set_title("close-up of the paths (axes not to scale)", fontsize=9)

    panels = defaultdict(list)  # label -> [(vehicle, lines)]
    for name, data in vehicles.items():
        state, desired, command, forces = data["state"], data["desired"], data["input"], data["forces"]
        t = state["t"]
        heading = np.degrees(np.unwrap(state["psi"]))
        desired_heading = _same_turn(desired.get("t"), desired.get("psi_d"), t, heading)
        panels["psi [deg]"].append((name, [(t, heading, "actual"), (desired.get("t"), desired_heading, "desired")]))
        panels["speed [m/s]"].append((name, [(t, state["u"], "u"), (desired.get("t"), desired.get("u_d"), "desired")]))
        panels["rudder [deg]"].append((name, [(command.get("t"), _degrees(command.get("delta_r")), "rudder")]))
        panels["thrust [N]"].append((name, [(command.get("t"), command.get("X_prop"), "thrust")]))
        if forces:
            # What entered the dynamics: the blend weight is 0 outside the surrogate's domain, where
            # the raw prediction is published but not applied.
            applied = {axis: forces["weight"] * forces[axis] for axis in ("X_s", "Y_s", "N_s")}
            lines = [(forces["t"], applied[axis], axis) for axis in ("X_s", "Y_s", "N_s")]
            panels["applied X_s, Y_s [N]"].append((name, lines))
    for row, (label, items) in enumerate(panels.items()):
        panel = fig.add_subplot(grid[row, 1])
        moment = panel.twinx() if label.startswith("applied") else None  # N_s is a moment: its own axis
        for name, lines in items:
            for number, (x, y, what) in enumerate(lines):
                if x is None or y is None or not len(x):
                    continue
                target = moment if what == "N_s" else panel
                style = {"color": "tab:green"} if single and what == "N_s" else {}
                if not single:  # one colour per vehicle; its second and third lines dashed and dotted
                    style = {"color": colours[name], "ls": ("-", "--", ":")[number]}
                target.step(x, y, where="post", label=what if single else f"{name} {what}", lw=1, **style)
        panel.set_ylabel(label)
        panel.grid(alpha=0.3)
        handles = panel.get_legend_handles_labels()[0]
        if moment is not None:
            moment.set_ylabel("N_s [N m]")
            handles += moment.get_legend_handles_labels()[0]
        panel.legend(handles=handles, loc="best", fontsize=7)
    panel.set_xlabel("simulated time [s]")
    output = Path(output) if output else Path(path).with_suffix(".png")
    fig.savefig(output, dpi=110)
    plt.close(fig)
    return output

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
from nearsub.common.runtime.logfile import read_log  # noqa: E402
from nearsub.common.viewer.scene import frame_description  # noqa: E402

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


def draw_plan(ax, mission, state: dict[str, np.ndarray], events: list[dict]) -> None:
    """The plan view in the submarine frame: hull outline, track-lines and waypoints, the UUV's
    path and the events that carry a position."""
    if mission is None or mission.environment.submarine:
        sx, sy = submarine_outline()
        ax.fill(sx, sy, color="0.8", label="submarine")
    if mission is not None:
        previous = (mission.start.x, mission.start.y)
        for number, leg in enumerate(mission.apps.helm.legs):
            points = np.array(leg.points)
            track = np.vstack([previous, points])
            ax.plot(track[:, 0], track[:, 1], "b--", lw=1, label=None if number else "track-lines")
            ax.plot(points[:, 0], points[:, 1], "bs", ms=5, label=None if number else "waypoints")
            previous = tuple(points[-1])
    ax.plot(state["x"], state["y"], "r-", lw=1.5, label="UUV")
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
    contents = read_log(path)
    resolved = contents.metadata.get("mission", {}).get("resolved")
    mission = mission_from_dict(json.loads(resolved)) if resolved else None
    state = series(contents.records, "state")
    desired = series(contents.records, "desired")
    command = series(contents.records, "input")
    forces = series(contents.records, "forces")
    if not state:
        raise ValueError(f"{path}: no state messages to plot")

    fig = plt.figure(figsize=(15, 10), constrained_layout=True)
    grid = fig.add_gridspec(5, 2, width_ratios=[1.2, 1])
    overview = fig.add_subplot(grid[:3, 0])
    close_up = fig.add_subplot(grid[3:, 0])
    events = [r.value() for r in contents.records if "/events/" in r.topic]
    for ax in (overview, close_up):
        draw_plan(ax, mission, state, events)
    overview.set_aspect("equal", adjustable="datalim")
    overview.legend(loc="best", fontsize=8)
    outcome = contents.metadata.get("outcome", {})
    overview.set_title(title or f"{Path(path).stem}: {outcome.get('outcome', '?')}")
    # The close-up frames the UUV's path at free aspect: beside an 89 m hull, deviations of a
    # few decimetres are what decides a collision, and they vanish at equal scales.
    for axis, values in ((close_up.set_xlim, state["x"]), (close_up.set_ylim, state["y"])):
        margin = max(0.1 * np.ptp(values), 1.0)
        axis(values.min() - margin, values.max() + margin)
    close_up.set_title("close-up of the path (axes not to scale)", fontsize=9)

    t = state["t"]
    heading = np.degrees(np.unwrap(state["psi"]))
    panels = [
        (
            "heading [deg]",
            [
                (t, heading, "actual"),
                (desired.get("t"), _same_turn(desired.get("t"), desired.get("psi_d"), t, heading), "desired"),
            ],
        ),
        ("speed [m/s]", [(t, state["u"], "u"), (desired.get("t"), desired.get("u_d"), "desired")]),
        ("rudder [deg]", [(command.get("t"), _degrees(command.get("delta_r")), "rudder")]),
        ("thrust [N]", [(command.get("t"), command.get("X_prop"), "thrust")]),
    ]
    if forces:
        # What entered the dynamics: the blend weight is 0 outside the surrogate's domain, where
        # the raw prediction is published but not applied.
        applied = {name: forces["weight"] * forces[name] for name in ("X_s", "Y_s", "N_s")}
        panels.append(("applied X_s, Y_s [N]", [(forces["t"], applied[name], name) for name in ("X_s", "Y_s")]))
    for row, (label, lines) in enumerate(panels):
        panel = fig.add_subplot(grid[row, 1])
        for x, y, name in lines:
            if x is not None and y is not None and len(x):
                panel.step(x, y, where="post", label=name, lw=1)
        panel.set_ylabel(label)
        panel.grid(alpha=0.3)
        if forces and row == len(panels) - 1:
            moment = panel.twinx()  # N_s is a moment: its own axis
            moment.step(forces["t"], applied["N_s"], where="post", color="tab:green", lw=1, label="N_s")
            moment.set_ylabel("N_s [N m]")
            handles = panel.get_legend_handles_labels()[0] + moment.get_legend_handles_labels()[0]
            panel.legend(handles=handles, loc="best", fontsize=7)
        else:
            panel.legend(loc="best", fontsize=7)
    panel.set_xlabel("simulated time [s]")
    output = Path(output) if output else Path(path).with_suffix(".png")
    fig.savefig(output, dpi=110)
    plt.close(fig)
    return output

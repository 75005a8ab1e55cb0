"""Autonomy: what the helm and the controller decide.

- behaviours: helm behaviours (waypoints, modified waypoints, N_uv compensation) as pure functions.
- control: the speed and heading PID of thesis (5.21), positional and incremental.
- pid_design: the library PID gains, designed from the linearised vehicle.
"""

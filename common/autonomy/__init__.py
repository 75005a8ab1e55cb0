"""Autonomy: what the helm and the controller decide.

- behaviours: the thesis's waypoint geometry (5.7, 6.3.2) and N_uv compensation (6.1) as pure functions.
- helm: behaviours as objective functions, their settings, and the helm (conditions, flags, modes).
- prediction_kernel: the hull avoidance's compiled prediction of each candidate command.
- ivp: objective functions over (heading, speed) and their arbitration by priority.
- logic: mission variables, logic conditions and hierarchical modes.
- control: the speed and heading PID of thesis (5.21), positional and incremental.
- pid_design: the library PID gains, designed from the linearised vehicle.
"""

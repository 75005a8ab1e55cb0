"""The functional core of nearsub: plain Python and numpy, no Zenoh outside runtime.bus.

Sub-packages by subject, each depending only on those listed before it: runtime, physics,
autonomy, hydro, learning, surrogate, mission, analysis.
"""

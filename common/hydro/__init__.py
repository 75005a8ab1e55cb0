"""Hydrodynamic models of the UUV-submarine interaction, the fidelities the surrogate learns from.

- low_fidelity: one-way slender-body model in the submarine's potential flow (fast).
- high_fidelity: two-way source panel model of both hulls with viscous corrections (slow).
- free_stream: free-stream tables of a model (the UUV alone), for the interaction increment.
- cache: a disk cache of start-up tables (the LF's submarine field), keyed by the code that makes them.
"""

"""Hydrodynamic models of the UUV-submarine interaction, the fidelities the surrogate learns from.

- low_fidelity: one-way slender-body model in the submarine's potential flow (fast).
- lf_kernel: the low fidelity's compiled kernels (field lookup and strip forces).
- high_fidelity: two-way source panel model of both hulls with viscous corrections (slow).
- rans: RANS CFD on OpenFOAM (simpleFoam, k-omega SST): cases, runs, forces, convergence verdict (hours).
- rans_geometry: the hulls as closed STL surfaces for the mesher.
- rans_campaign: case suites, the resumable runner, kept artefacts, the SUBOFF validation tables.
- cache: a disk cache of start-up tables (the LF's submarine field), keyed by the code that makes them.
"""

"""Gaussian processes and active learning, independent of the hydrodynamics.

- gp: single-output and multi-output GP regression (ARD RBF, type-II maximum likelihood).
- gp_kernel: the compiled kernel matrices and distances of `gp`.
- mfgp: two-fidelity AR(1) GP (thesis 2.2.4).
- active: acquisitions, NMMF (thesis algorithm 1) and its baselines, ask/tell campaigns.
- testproblems: benchmark problems of thesis sections 2.4-2.5.
- reference_gp: an independent multi-fidelity GP (emukit on GPy, `bench` extra), benchmark only.
- envelope_design: the envelope design's acquisition (variance explained along doubtful cells' trajectories).
"""

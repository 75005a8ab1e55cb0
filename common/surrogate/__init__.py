"""The interaction surrogate: its domain, model files, predictions, training and checks.

- domain: inputs, bounds, constraints (4.4)-(4.7) and unit conversions.
- model: the loaded surrogate, its predictions and the query messages of the surrogate server.
- modelfile: one versioned file per trained surrogate.
- interaction: the interaction forces the sim and the helm apply at a vehicle's state.
- interaction_kernel: the compiled domain arithmetic of each row (inputs, constraints, weights, x_c, flags, forces).
- free_stream: a model's free-stream table (the UUV alone), for the interaction increment.
- training: the training designs (sobol, residual-us, nmmf), HF runs and the final fit of the shipped surrogate.
- warping: input warpings applied before the unit-cube scaling (log clearance, log D_sub/D_uuv).
- sweeps: heading and lateral sweeps of the interaction increment (HF, LF, applied).
- maps: the thesis section 4.5 colour maps as data.
- validation: MAE against the high fidelity in the form of thesis table 4.3.
- calibration: the predicted std scaled so its two-sigma band covers the leave-one-out errors.
- sampling: posterior function samples of the residual GP, consistent along a trajectory.
- sampling_kernel: the compiled kernels of `sampling`.
- query: the surrogate server's query and reply messages.
- campaign_cases: a surrogate input as the dimensional case a CFD user sets up.
- viscous: the viscous correction, a model's increment taken towards RANS near the RANS stations.
"""

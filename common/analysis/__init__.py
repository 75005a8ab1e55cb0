"""Analysis: many runs at once (missions, benchmark campaigns), and what they show.

- batch: the vectorised engine, N UUVs through the very functions the apps call.
- envelope: operating envelopes (thesis 5.11, 6.4) and sweeps.
- envelope_design: HF samples aimed at named envelopes, pool mode's comparison of the designs.
- scenarios: figures of merit of the thesis scenarios.
- fleet: figures of merit of a mission of several vehicles.
- approach: a run's closest approaches to the hull and between UUVs (launch summary, log info).
- validation: the thesis section 5.10 validation cases.
- albench: the NMMF benchmark runner (repeats in parallel processes) and its summaries.
- rans_comparison: two-body RANS stations against the panel HF, the LF and the shipped model.
"""

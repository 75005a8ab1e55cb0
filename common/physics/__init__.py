"""Vehicle physics: everything a UUV obeys on its own, plus the hull geometry around it.

- vehicles: mass properties and hydrodynamic coefficients of the REMUS 100, NPS AUV II and SDV.
- dynamics: 3-DOF equations of motion (thesis 5.10/5.11) and their integrators.
- waves: deep-water linear waves for sea states 0-6 (thesis 5.22/5.23).
- hull: SUBOFF and Explorer hull shapes, outlines, profiles and panel meshes.
- proximity: collision, close-call and large-stray geometry (thesis 5.11.2).
- encounters: clearance, collision and close call between two UUVs (capsule hulls).
- proximity_kernel: its compiled grid reader and outline clearance (numba).
"""

"""MOOS-IvP in the loop: what nearsub's sim and missions are in a MOOS community, without MOOS.

- config: a .moos file's global parameters and ProcessConfig blocks, and the sim's block.
- bridge: MOOS variables to the sim's input, its state, forces and events to MOOS variables
  (frames, units, NODE_REPORT, the hull's VIEW_SEGLIST, AppCast), and MOOS time to the sim's steps.
- sim: the mission's SimCore driven by DESIRED_* mail and MOOS time (the MOOS app's core).
- watch: a running nearsub mission as MOOS variables for pMarineViewer (NODE_REPORT, VIEW_*).
"""

"""The launcher of `nearsub launch`: a mission as separate processes (the pAntler of nearsub).

Start order: router, then logger, surrogate server, sim, pid, helm (of each vehicle of a fleet:
`auv1/sim-1`, ..., docs/architecture.md, "Several vehicles") and clock at once. The router
is started on loopback port 0 and reports the endpoint it really listens on in a ready file; the
lock-stepped apps wait for the logger's and the server's liveliness before they publish, so
nothing is published before the logger listens, and the clock waits for them. Every wait is
bounded by the mission's startup_timeout, and so is every client's connect (on a loaded machine a
process may take seconds just to import). The launcher supervises every process it started, the
router, logger and surrogate server included: one that exits or crashes is reported with the step
within a fraction of a second, the mission is ended (the logger closes its file), and the rest is
stopped. A launch that fails before its logger started leaves no log folder behind. Stopping
escalates per process group: SIGINT, then SIGTERM, then SIGKILL, 5 s apart (ros2 launch's ladder).
Every process it starts gets the mission's environment handed to it (`bus.app_environment`); the
launcher's own environment is never changed.

- supervision: the run (`Launcher`): start everything, watch the processes and the bus until the
  mission ends, stop.
- processes: what the launcher started: spawning an app (fork server or its own process), the
  router, waiting for their liveliness, the stop order, their CPU.
- status: the lines for people, the terminal status line and the summary.
- swap: `nearsub swap`: pause the clock at a step boundary, start the new app instance, let it take
  over from the old one, retire the old one, resume.
- registration: the mission's name: claimed on the bus, entered in the registry, removed at the end.
"""

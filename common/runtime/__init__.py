"""Runtime: transport, messages and the lock-step protocol; knows nothing of physics.

- bus: the only Zenoh code (sessions, publishers, FIFO mailboxes, queries).
- endpoints: the one check of `<protocol>/<address>` endpoints.
- credentials: the mission's user:password file for Zenoh's authentication (create, load).
- keys: build and parse every key expression.
- messages: wire messages (pydantic models, msgpack codec, topic -> model registry).
- fields: each message field's unit and frame, and the degrees people read and type (docs/messages.md).
- lifecycle: the app core protocol (start-up, new mail, iterate), schedule, step runner and in-process runner.
- clock: the clock's grants, pauses and stall timer (ClockCore), free of transport and of the wall clock.
- logfile: MCAP mission logs (write and read).
- alog: a mission log as a MOOS-IvP alog (the vehicle library handed in: no physics here).
- processes: the processes nearsub starts: one BLAS thread, spawning apps, the stop ladder, Dask tasks.
- forkserver: the apps' pre-imported parent: forks each app with the shared modules loaded.
"""

"""Runtime: transport, messages and the lock-step protocol; knows nothing of physics.

- bus: the only Zenoh code (sessions, publishers, FIFO mailboxes, queries).
- keys: build and parse every key expression.
- messages: wire messages (pydantic models, msgpack codec, topic -> model registry).
- lifecycle: the app core protocol (start-up, new mail, iterate), the schedule, the inbox and the in-process runner.
- clock: the clock's grant, pause and stall bookkeeping, free of transport.
- logfile: MCAP mission logs (write and read).
- processes: the processes nearsub starts: one BLAS thread, spawning apps, the stop ladder.
"""

"""Where running missions can be found: one small JSON file per community in a runtime folder.

The launcher writes `<community>.json` (router endpoint, launcher pid, log path, the path of the
mission's credentials file) when it starts and removes it when it stops; `tap` and `swap` read it
so that users can name a community instead of an endpoint. Set NEARSUB_RUNTIME_DIR to move the
folder (the tests do, to stay isolated).

A launcher first claims its name (`claim`): an exclusive `flock` on `<community>.lock`, taken
without waiting and held until the launcher exits. The kernel drops the lock when the process
dies, however it dies, so a stale claim needs no clean-up and two launches of one name racing
each other cannot both win (flock(2); the JSON file is written only later, once the apps are up).
The folder must be the user's and writable by no one else, and its files are opened without
following symbolic links: a link planted as `<community>.lock` or `<community>.json` would
otherwise have the launcher write through it to a file of the planter's choosing.

The lock file stays when released: unlocked it means nothing, and removing it would let a launch
that opened the old file and one that creates a new file both hold "the" lock.
"""

from __future__ import annotations

import fcntl
import json
import os
import stat
import tempfile
import time
from pathlib import Path


class NameTaken(LookupError):
    """Another live launcher holds this mission name."""


class Claim:
    """The held claim on a mission name; `release` (or process exit) gives it up."""

    def __init__(self, community: str, fd: int):
        self.community = community
        self._fd = fd

    def release(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)  # closing the descriptor drops the flock
            self._fd = -1

    def __enter__(self) -> Claim:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def claim(community: str) -> Claim:
    """Claim `community` for this process, or raise NameTaken naming the launcher that holds it.
    First clear what dead launchers left (`sweep`)."""
    sweep()
    path = runtime_dir() / f"{community}.lock"
    fd = open_private(path, os.O_RDWR | os.O_CREAT)
    if not _lock(fd, patience=SWEEP_PATIENCE):
        holder = _holder(fd) or "unknown"
        os.close(fd)
        raise NameTaken(
            f"a mission named {community!r} is already running (launcher pid {holder}); use --set name=OTHER"
        ) from None
    os.ftruncate(fd, 0)
    os.pwrite(fd, str(os.getpid()).encode(), 0)
    return Claim(community, fd)


SWEEP_PATIENCE = 1.0  # seconds a claim waits for another launch's sweep of the name (microseconds)


def _holder(fd: int) -> str:
    return os.pread(fd, 32, 0).decode(errors="replace").strip()


def _lock(fd: int, patience: float = 0.0) -> bool:
    """Take the name's flock without waiting; a lock whose recorded launcher is dead is another
    launch's `sweep`, so that one is waited for, up to `patience` seconds."""
    deadline = time.monotonic() + patience
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            holder = _holder(fd)
            if time.monotonic() > deadline or (holder.isdigit() and _pid_alive(int(holder))):
                return False
            time.sleep(0.01)


def sweep() -> None:
    """Remove the credentials and registry entries of launchers that died without cleaning up
    (SIGKILL, a crash): a name whose lock no live process holds, checked by taking the lock itself,
    so a live launcher's files are never touched. The lock files stay (see above)."""
    folder = runtime_dir()
    for lock in folder.glob("*.lock"):
        community = lock.name.removesuffix(".lock")
        leftovers = [folder / f"{community}.json", credentials_path(community)]
        if not any(path.exists() or path.is_symlink() for path in leftovers):
            continue
        try:
            fd = open_private(lock, os.O_RDWR)
        except (OSError, LookupError):
            continue
        try:
            if _lock(fd):  # nobody holds the name: its launcher is gone
                for path in leftovers:
                    path.unlink(missing_ok=True)
        finally:
            os.close(fd)


def runtime_dir() -> Path:
    """The folder, private to this user (mode 0700): it holds the missions' credentials. One in
    the shared temporary folder that another user owns is refused (they made it to read ours)."""
    default = Path(tempfile.gettempdir()) / f"nearsub-{os.getuid()}"
    path = Path(os.environ.get("NEARSUB_RUNTIME_DIR", default))
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    status = path.stat()
    if status.st_uid != os.getuid():
        raise LookupError(f"runtime folder {path} belongs to another user; set NEARSUB_RUNTIME_DIR")
    if status.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        mode = stat.S_IMODE(status.st_mode)
        raise LookupError(f"runtime folder {path} has mode {mode:o}: others can write to it; chmod 700 {path}")
    return path


def open_private(path: Path, flags: int) -> int:
    """`os.open` of a file of the runtime folder, never through a symbolic link (mode 0600 when
    created); a link there is refused as a LookupError naming it."""
    try:
        return os.open(path, flags | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
    except OSError:
        if path.is_symlink():
            raise LookupError(f"{path} is a symbolic link, not the file nearsub made; remove it") from None
        raise


def _read_entry(path: Path) -> dict:
    with os.fdopen(open_private(path, os.O_RDONLY)) as source:
        return json.loads(source.read())


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def credentials_path(community: str) -> Path:
    """Where a launcher that starts its own router keeps the mission's credentials."""
    return runtime_dir() / f"{community}.credentials"


def register(
    community: str, endpoint: list[str], log: str, credentials: str | None = None, vehicles: list[str] = ()
) -> Path:
    """Make the mission findable; `credentials` is the file its router requires (None: open);
    `vehicles` the names of its [[vehicles]] (empty without)."""
    path = runtime_dir() / f"{community}.json"
    entry = {"community": community, "connect": endpoint, "pid": os.getpid(), "log": log, "credentials": credentials}
    entry["vehicles"] = list(vehicles)
    # A new file, renamed over the old entry (a rename replaces a link itself, never its target),
    # so a reader never sees a half-written entry.
    fresh = path.with_name(f".{path.name}.{os.getpid()}")
    fresh.unlink(missing_ok=True)
    with os.fdopen(open_private(fresh, os.O_WRONLY | os.O_CREAT | os.O_EXCL), "w") as out:
        out.write(json.dumps(entry))
    os.replace(fresh, path)
    return path


def running() -> dict[str, dict]:
    """Communities whose launcher is still alive (stale entries are removed)."""
    found = {}
    for path in runtime_dir().glob("*.json"):
        try:
            entry = _read_entry(path)
        except (OSError, ValueError, LookupError):
            continue
        if _pid_alive(int(entry.get("pid", -1))):
            found[entry["community"]] = entry
        else:
            path.unlink(missing_ok=True)
    return found


def lookup(community: str) -> dict:
    """The entry of the running mission `community`; a LookupError naming it, the running ones and
    the closest of them (did you mean) when it is not running."""
    missions = running()
    if community in missions:
        return missions[community]
    if not missions:
        raise LookupError(f"no running mission named {community!r} (none is running; start one with `nearsub launch`)")
    import difflib

    close = difflib.get_close_matches(community, missions, n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    raise LookupError(f"no running mission named {community!r} ({hint}running: {', '.join(sorted(missions))})")

"""Per-mission credentials for Zenoh's user/password authentication (docs/design.md, "Transport").

One file holds them, in the format of Zenoh's own `dictionary_file`: a single `user:password`
line. The router is given the file as its dictionary, and every client reads the same pair from
it, so one file serves both sides. It is created with mode 0600 and refused when anyone but its
owner may read it, as ssh refuses a private key: the file is the only thing that lets a process
into a mission.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
import stat
from dataclasses import dataclass
from pathlib import Path

# Where the processes a launcher starts find the file; tools may set it by hand (multi-host).
VARIABLE = "NEARSUB_CREDENTIALS"


class CredentialsError(ValueError):
    """A credentials file that cannot be used; the one-line text names the file and why."""


@dataclass(frozen=True)
class Credentials:
    path: Path
    user: str
    password: str


def create(path: str | Path) -> Credentials:
    """Write a fresh random user and password to `path` (replacing any old file), mode 0600."""
    path = Path(path)
    user, password = f"nearsub-{secrets.token_hex(4)}", secrets.token_urlsafe(24)  # no ':' in either
    path.unlink(missing_ok=True)
    # O_EXCL|O_NOFOLLOW: never write through a file or link someone else put there meanwhile.
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
    with os.fdopen(fd, "w") as out:
        out.write(f"{user}:{password}\n")
    return Credentials(path, user, password)


def load(path: str | Path) -> Credentials:
    """The credentials in `path`; CredentialsError when missing, readable by others or malformed."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError as exc:
        raise CredentialsError(f"credentials file {path}: {exc.strerror}") from None
    with os.fdopen(fd) as source:
        mode = os.fstat(source.fileno()).st_mode
        if mode & (stat.S_IRWXG | stat.S_IRWXO):
            raise CredentialsError(
                f"credentials file {path}: mode {stat.S_IMODE(mode):o} lets others read it; chmod 600 {path}"
            )
        lines = [line.strip() for line in source.read().splitlines() if line.strip()]
    user, sep, password = lines[0].partition(":") if len(lines) == 1 else ("", "", "")
    if not (sep and user and password):
        raise CredentialsError(f"credentials file {path}: expected one line 'user:password'")
    return Credentials(path, user, password)


def derive(credentials: Credentials, purpose: str) -> str:
    """A secret for `purpose` (e.g. the viewer's control token) that only holders of the
    credentials can compute: HMAC-SHA256 of the purpose keyed by the password, 32 hex digits."""
    return hmac.new(credentials.password.encode(), purpose.encode(), hashlib.sha256).hexdigest()[:32]


def from_environment() -> str | None:
    """The credentials file named by $NEARSUB_CREDENTIALS, if set."""
    return os.environ.get(VARIABLE) or None

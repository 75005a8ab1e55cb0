"""A launch's mission name: refused when another launcher uses it on the same bus, entered in the
registry (tools/support/registry.py) once the apps are up so that the tools find the mission, and removed
with the credentials of the launcher's own router at the end."""

from __future__ import annotations

import uuid
from pathlib import Path

from nearsub.common.mission.schema import Mission
from nearsub.common.runtime import keys

from ..support import registry


def credentials_file(mission: Mission) -> str | None:
    """The credentials file of the mission's router: `network.credentials` for a router given by
    `network.connect` (None: an open one), else the file the launcher's own router gets."""
    network = mission.network
    if network.connect:
        return str(Path(network.credentials).resolve()) if network.credentials else None
    return str(registry.credentials_path(mission.name))


def claim_on_bus(bus, community: str, connect: list[str], timeout: float) -> None:
    """Refuse a name another launcher uses on this bus (missions sharing a router, maybe from
    other hosts; the registry's lock covers this host). A claim token is declared first and
    then the claims and launcher tokens alive are listed, so of two launchers racing through
    one router at least the later one sees the other (both refuse when they cross exactly)."""
    root = f"{keys.community_root(community)}/launcher/claim"
    mine = f"{root}/{uuid.uuid4().hex}"
    bus.token(mine)
    timeout = min(2.0, timeout)
    others = [k for k in bus.alive(f"{root}/*", timeout=timeout) if k != mine]
    others += bus.alive(keys.alive(community, "launcher", "*"), timeout=timeout)
    if others:
        raise registry.NameTaken(
            f"a mission named {community!r} is already running or starting on {', '.join(connect)}; "
            "use --set name=OTHER"
        )


def register(mission: Mission, connect: list[str], log_path: Path, credentials: str | None) -> None:
    """Make the running mission findable by name (`tap`, `swap`, `clock`, `view`, ...)."""
    names = mission.vehicle_names if mission.fleet else []
    registry.register(mission.name, connect, str(log_path), credentials, names)


def forget(mission: Mission) -> None:
    """Remove the mission's registry entry, and the credentials of the launcher's own router: the
    next launch of the name makes new ones."""
    (registry.runtime_dir() / f"{mission.name}.json").unlink(missing_ok=True)
    if not mission.network.connect:
        registry.credentials_path(mission.name).unlink(missing_ok=True)

"""The topic a command is given (`tap echo MISSION KEY`, `tap hz MISSION KEY`, `log export --topic
KEY`): a key expression, or a short key (`state`, `desired`, `input`, `forces`, `events`, ...) that
stands for that topic of every vehicle of the mission. Given the mission, a key expression that does
not start with `nearsub/` is relative to it (`auv1/state`, `*/forces`, `**`), and one of another
mission is bad input. A bare word that is neither is bad input naming the short keys."""

from __future__ import annotations

from .errors import InputError


def topic_key(key: str, community: str | None = None, option: str = "") -> str:
    """`key` as a key expression: a short key expanded for `community` (None: any mission), a key
    with a `/` or a wildcard under `community` (as it is without one). `option` names the argument
    in the error (`--topic`)."""
    from nearsub.common.runtime.messages import SHORT_KEYS, short_key

    if "/" in key or "*" in key:
        if community is None:
            return key
        if not key.startswith("nearsub/"):
            return f"nearsub/{community}/{key}"
        owner = key.split("/")[1] if key.count("/") else ""
        if owner not in (community, "*", "**"):
            raise InputError(
                f"{option or 'key'} {key}: not a key of mission {community!r} (give nearsub/{community}/... "
                "or a key relative to the mission, such as */state)"
            )
        return key
    expanded = short_key(key, community)
    if expanded is None:
        where = f"{option or 'key'} {key}"
        raise InputError(
            f"{where}: not a short key ({', '.join(SHORT_KEYS)}) nor a key expression such as nearsub/MISSION/*/state"
        )
    return expanded

"""The topic a command is given (`tap echo KEY`, `tap hz KEY`, `log export --topic KEY`): a key
expression, or a short key (`state`, `desired`, `input`, `forces`, `events`, ...) that stands for
that topic of every vehicle of the mission. A bare word that is neither is bad input naming the
short keys."""

from __future__ import annotations

from .errors import InputError


def topic_key(key: str, community: str | None = None, option: str = "") -> str:
    """`key` as a key expression: a short key expanded for `community` (None: any mission), a key
    with a `/` or a wildcard as it is. `option` names the argument in the error (`--topic`)."""
    from nearsub.common.runtime.messages import SHORT_KEYS, short_key

    if "/" in key or "*" in key:
        return key
    expanded = short_key(key, community)
    if expanded is None:
        where = f"{option or 'key'} {key}"
        raise InputError(
            f"{where}: not a short key ({', '.join(SHORT_KEYS)}) nor a key expression such as nearsub/MISSION/*/state"
        )
    return expanded

"""Key expressions (docs/design.md, "Topics and messages"): nearsub/<community>/<vehicle>/<topic>
for vehicle data and nearsub/<community>/<service>/... for the clock, events, status and
services."""

ROOT = "nearsub"


def app_name(vehicle: str | None, role: str) -> str:
    """A lock-stepped app's name: its role for a mission without [[vehicles]], else
    `<vehicle>/<role>` (docs/architecture.md, "Processes"), which adds a key chunk wherever the
    name appears (acks, liveliness, status, events, control)."""
    return role if vehicle is None else f"{vehicle}/{role}"


def split_app(name: str) -> tuple[str | None, str]:
    """`app_name`'s inverse: (vehicle or None, role)."""
    vehicle, _, role = name.rpartition("/")
    return vehicle or None, role


def community_root(community: str) -> str:
    return f"{ROOT}/{community}"


def vehicle_topic(community: str, vehicle: str, leaf: str) -> str:
    return f"{ROOT}/{community}/{vehicle}/{leaf}"


def feed(community: str, vehicle: str, leaf: str, stride: int) -> str:
    """The outputs of a vehicle topic labelled with multiples of `stride`, for the apps that read
    only those (`lifecycle.Schedule.stride`: the helm of period 5 and the sim's state): a copy of
    what the topic carries, under a verbatim chunk (`@every5`) that no wildcard matches, so the
    logger, `tap` and the viewers, subscribed with `**` or `*`, never see it twice."""
    return f"{vehicle_topic(community, vehicle, leaf)}/@every{stride}"


def tick(community: str) -> str:
    return f"{ROOT}/{community}/clock/tick"


def ack(community: str, app: str) -> str:
    return f"{ROOT}/{community}/clock/ack/{app}"


def clock_traffic(community: str) -> str:
    """The clock's ticks, the apps' acks and the mission end: what every lock-stepped app hears."""
    return f"{ROOT}/{community}/clock/**"


def all_acks(community: str) -> str:
    return f"{ROOT}/{community}/clock/ack/**"


def mission_end(community: str) -> str:
    return f"{ROOT}/{community}/clock/end"


def events(community: str, source: str) -> str:
    return f"{ROOT}/{community}/events/{source}"


def all_events(community: str) -> str:
    return f"{ROOT}/{community}/events/**"


def status(community: str, instance: str) -> str:
    return f"{ROOT}/{community}/status/{instance}"


def alive(community: str, role: str, instance: str) -> str:
    """Liveliness token of one app instance; the role (helm, sim, ..., or a vehicle's app such as
    auv1/helm) survives a swap. An instance named after its vehicle (auv1/helm-1) adds only its
    last chunk."""
    return f"{ROOT}/{community}/alive/{role}/{instance.rsplit('/', 1)[-1]}"


def alive_role(key: str) -> str:
    """The role (app name) of a liveliness key made by `alive`."""
    return key.split("/alive/", 1)[1].rsplit("/", 1)[0]


def all_alive(community: str) -> str:
    return f"{ROOT}/{community}/alive/**"


def control(community: str, target: str) -> str:
    """Requests to one app instance ("clock" for the clock): pause, handover, retire, ..."""
    return f"{ROOT}/{community}/control/{target}"


def reply(community: str, requester: str) -> str:
    return f"{ROOT}/{community}/reply/{requester}"


def launcher_control(community: str) -> str:
    return f"{ROOT}/{community}/launcher/control"


def everything(community: str) -> str:
    """The whole community: only the logger subscribes to it."""
    return f"{ROOT}/{community}/**"


# The chunks after the community that are mission-wide, not a vehicle's name.
SERVICES = frozenset({"clock", "events", "status", "alive", "control", "reply", "launcher", "surrogate"})


def vehicle_of(key: str) -> tuple[str, str] | None:
    """(vehicle, leaf) of a vehicle key nearsub/<c>/<vehicle>/<leaf>[/...] (the leaf is the first
    chunk after the vehicle), or (vehicle, "events") for the events of a vehicle's app, whose
    instance name `<vehicle>/<app>` adds a chunk (nearsub/<c>/events/<vehicle>/<instance>); None
    for a mission-wide key. Readers find a mission's vehicles this way."""
    parts = key.split("/")
    if len(parts) < 4 or parts[0] != ROOT:
        return None
    if parts[2] == "events" and len(parts) >= 5:
        return parts[3], "events"
    return None if parts[2] in SERVICES else (parts[2], parts[3])

"""`nearsub tap list|echo|hz|watch|pub MISSION ...`: watch a running mission (uXMS / `ros2 topic`).
MISSION is the running mission's name (tools/support/missions.py); KEY a short key such as `state`,
or a key expression, relative to the mission unless it starts with `nearsub/` (tools/support/topics.py)."""

from __future__ import annotations

import json
import sys
import time
from collections import defaultdict, deque

from ..support.arguments import integer, number
from ..support.connect import add_connect_arguments, open_bus
from ..support.errors import InputError
from ..support.missions import resolve_mission
from ..support.topics import topic_key

KEY_HELP = (
    "a short key: state, desired, input, forces, ... (every vehicle's), or a key expression (wildcards * and **) "
    "relative to the mission (auv1/state, */forces) unless it starts with nearsub/"
)

PUB_VALUE_HELP = (
    "JSON object of fields; an angle may be given in degrees as NAME_deg, as tap echo prints it on a terminal "
    '(\'{"u_d": 1.5, "psi_d_deg": 30}\')'
)


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("tap")
    tap = p.add_subparsers(dest="tap_command", required=True)
    t = tap.add_parser("list", help="apps alive now, and topics with their message types and rates")
    add_connect_arguments(t)
    t.add_argument(
        "--sample", type=number(minimum=0.0), default=1.0, metavar="S", help="wall seconds to measure the rates over"
    )
    t.add_argument("--json", action="store_true")
    t.add_argument("--vehicle", metavar="NAME", help="only this vehicle's topics (and the apps)")
    t.set_defaults(func=tap_list)
    t = tap.add_parser("echo", help="print messages of a key expression (wildcards * and **)")
    add_connect_arguments(t)
    t.add_argument("key", metavar="KEY", help=KEY_HELP)
    t.add_argument(
        "--field", action="append", help="print only this field (dotted path); given again, a map of the fields"
    )
    t.add_argument("--count", type=integer(minimum=1), help="stop after N messages")
    t.add_argument("--timeout", type=number(above=0.0), help="stop after S wall seconds (or at the mission end)")
    t.add_argument("--json", action="store_true", help="JSON lines (the default when piped)")
    t.add_argument("--vehicle", metavar="NAME", help="only the keys of this vehicle (nearsub/<c>/NAME/...)")
    t.set_defaults(func=tap_echo)
    t = tap.add_parser("hz", help="message rates per key, in simulated time")
    add_connect_arguments(t)
    t.add_argument("key", metavar="KEY", help=KEY_HELP)
    t.add_argument("--window", type=integer(minimum=2), default=100, help="samples per rate estimate")
    t.add_argument("--vehicle", metavar="NAME", help="only the keys of this vehicle (nearsub/<c>/NAME/...)")
    t.add_argument("--duration", type=number(above=0.0), default=5.0, help="wall seconds to listen")
    t.add_argument("--json", action="store_true")
    t.set_defaults(func=tap_hz)
    t = tap.add_parser("watch", help="a table of the newest value on each key, refreshed as they come (uXMS)")
    add_connect_arguments(t)
    t.add_argument("keys", nargs="+", metavar="KEY", help=KEY_HELP)
    t.add_argument("--field", action="append", help="a column: this field (dotted path); default: the whole value")
    t.add_argument("--vehicle", metavar="NAME", help="only the keys of this vehicle (nearsub/<c>/NAME/...)")
    t.add_argument(
        "--timeout", type=number(above=0.0), help="stop after S wall seconds (default: at Ctrl-C or the mission end)"
    )
    t.add_argument("--json", action="store_true", help="at the end, one JSON line per key (the default when piped)")
    t.set_defaults(func=tap_watch)
    t = tap.add_parser("pub", help="publish one message by hand, validated against its schema")
    add_connect_arguments(t)
    t.add_argument("key", metavar="KEY", help="one key: VEHICLE/LEAF (auv1/desired), or nearsub/MISSION/...")
    t.add_argument("value", nargs="?", default="{}", help=PUB_VALUE_HELP)
    t.add_argument("--no-validate", action="store_true", help="send the JSON as msgpack without checking it")
    t.add_argument("--raw-hex", help="send these bytes instead (fault injection)")
    t.set_defaults(func=tap_pub)


def _project(value: dict, fields: list[str] | None):
    """The value, one field of it, or a map of several (`--field`, dotted paths)."""
    if not fields:
        return value
    if len(fields) > 1:
        return {field: _field(value, field) for field in fields}
    return _field(value, fields[0])


def _model_name(key: str) -> str:
    from nearsub.common.runtime.messages import model_for_key

    return getattr(model_for_key(key), "__name__", "")


def _for_people(key: str, value, fields: list[str] | None):
    """A message and its `--field`s as people read them (common/runtime/fields.py): angles in
    degrees under NAME_deg; one angle field alone becomes a map, so its name says the unit."""
    from nearsub.common.runtime.fields import for_people, people_name

    if not isinstance(value, dict):
        return value
    model = _model_name(key)
    shown = for_people(model, value)
    if not fields:
        return shown
    names = [people_name(model, field) for field in fields]
    if len(names) == 1 and names != fields:
        return {names[0]: _field(shown, names[0])}
    return _project(shown, names)


def _field(value: dict, field: str):
    for part in field.split("."):
        if isinstance(value, dict) and part in value:
            value = value[part]
        elif isinstance(value, list) and part.isdigit() and int(part) < len(value):
            value = value[int(part)]
        else:
            raise KeyError(f"field {field!r} not found (at {part!r})")
    return value


def _decode_any(key: str, payload: bytes) -> tuple[dict | None, str | None]:
    import msgpack

    from nearsub.common.runtime.messages import MessageError, decode, model_for_key

    model = model_for_key(key)
    try:
        if model is not None:
            return decode(payload, model, key).model_dump(mode="json"), None
        return msgpack.unpackb(payload), None
    except (MessageError, ValueError, msgpack.ExtraData) as exc:
        return None, str(exc)


def vehicle_name(key: str) -> str | None:
    """The vehicle a key belongs to (None: mission-wide)."""
    from nearsub.common.runtime.keys import vehicle_of

    owner = vehicle_of(key)
    return owner[0] if owner else None


def publishing_vehicles(bus, community: str) -> list[str]:
    """The vehicles with a publisher now in `community`."""
    from nearsub.common.runtime import keys

    prefix = keys.community_root(community) + "/"
    return sorted(
        {name for key in bus.admin_keys("publisher") if key.startswith(prefix) and (name := vehicle_name(key))}
    )


def check_vehicle(args, vehicles: list[str]) -> None:
    """InputError when `--vehicle` names none of `vehicles`."""
    if args.vehicle is not None and args.vehicle not in vehicles:
        raise InputError(f"--vehicle {args.vehicle}: no such vehicle (seen: {', '.join(vehicles) or 'none'})")


def check_key(key: str) -> None:
    """InputError naming a key expression Zenoh would refuse (before the bus is opened)."""
    from nearsub.common.runtime.bus import key_problem

    if problem := key_problem(key):
        raise InputError(f"{key!r} is not a key expression: {problem}")


class MissionWatch:
    """The running mission's apps, followed by their liveliness tokens in a tap's own mailbox
    ("alive" and "gone" mail, in order with its messages): the mission has ended once its last
    token has gone. A replay's player and a launch's launcher hold theirs until everything they
    publish is out, so the mission's messages are in the mailbox before that last "gone". With
    no community (a router given by --connect and no mission named) nothing is followed."""

    def __init__(self, bus, community: str | None, mailbox) -> None:
        from nearsub.common.runtime import keys

        self.tokens: set[str] = set()
        self.ended = False
        if community is not None:
            bus.watch_liveliness(keys.all_alive(community), mailbox, history=True)

    def took(self, mail) -> bool:
        """Whether `mail` was a token's news (then it is no message for the tap)."""
        if mail.kind == "alive":
            self.tokens.add(mail.key)
        elif mail.kind == "gone":
            self.tokens.discard(mail.key)
            self.ended = not self.tokens
        return mail.kind in ("alive", "gone")


def other_vehicle(args, key: str) -> bool:
    """A key that `--vehicle` leaves out."""
    return args.vehicle is not None and vehicle_name(key) != args.vehicle


def tap_list(args) -> int:
    from nearsub.common.runtime import keys

    bus, community = open_bus(args)  # first: with nothing running it says so before Zenoh loads
    from nearsub.common.runtime.bus import Mailbox
    from nearsub.common.runtime.messages import model_for_key

    times: dict[str, list[float]] = defaultdict(list)
    with bus:
        prefix = keys.community_root(community)
        mailbox = Mailbox()
        bus.subscribe(f"{prefix}/**", mailbox)
        apps = bus.alive(f"{prefix}/alive/**")
        publishers = [k for k in bus.admin_keys("publisher") if k.startswith(prefix)]
        subscribers = [k for k in bus.admin_keys("subscriber") if k.startswith(prefix)]
        deadline = time.monotonic() + args.sample
        while (remaining := deadline - time.monotonic()) > 0:
            mail = mailbox.get(timeout=remaining)
            if mail is not None:
                value, error = _decode_any(mail.key, mail.payload)
                if not error and isinstance(value, dict) and "t" in value:
                    times[mail.key].append(float(value["t"]))
    topics = sorted(set(publishers) | set(times))
    vehicles = sorted({name for key in topics if (name := vehicle_name(key))})
    if args.vehicle is not None:
        topics = [key for key in topics if not other_vehicle(args, key)]
    rows = [
        {
            "key": key,
            "vehicle": vehicle_name(key),
            "type": getattr(model_for_key(key), "__name__", ""),
            "hz": rate(times.get(key, [])),
        }
        for key in topics
    ]
    check_vehicle(args, vehicles)
    if args.json or not sys.stdout.isatty():
        listing = {"apps": apps, "vehicles": vehicles, "topics": rows}
        print(json.dumps(listing | {"publishers": publishers, "subscribers": subscribers}))
        return 0
    from rich.table import Table

    from ..support import tables

    console = tables.console()
    table = Table("app", "instance", title="apps alive", title_justify="left")
    for key in apps:
        table.add_row(keys.alive_role(key), key.rsplit("/", 1)[-1])  # a fleet's role is <vehicle>/<app>
    console.print(table)
    title = f"topics (rates over {args.sample:g} s); vehicles: {', '.join(vehicles) or 'none'}"
    table = Table("vehicle", "topic", "message", title=title, title_justify="left")
    table.add_column("Hz (simulated)", justify="right")
    for row in rows:
        table.add_row(row["vehicle"] or "-", row["key"], row["type"], f"{row['hz']:.2f}" if row["hz"] else "-")
    console.print(table)
    table = Table("subscription", title="subscriptions", title_justify="left")
    for key in subscribers:
        table.add_row(key)
    console.print(table)
    return 0


def rate(stamps) -> float:
    """Messages per simulated second over the simulated times `stamps` (oldest first)."""
    span = stamps[-1] - stamps[0] if len(stamps) > 1 else 0.0
    return (len(stamps) - 1) / span if span > 0 else 0.0


def tap_echo(args) -> int:
    as_json = args.json or not sys.stdout.isatty()
    key = topic_key(args.key, resolve_mission(args))
    check_key(key)  # a bare word that is no short key: said before the bus opens
    bus, community = open_bus(args)
    from nearsub.common.runtime.bus import Mailbox

    printed = 0
    deadline = time.monotonic() + args.timeout if args.timeout else None
    with bus:
        if args.vehicle is not None:
            check_vehicle(args, publishing_vehicles(bus, community))
        mailbox = Mailbox()
        bus.subscribe(key, mailbox)
        mission = MissionWatch(bus, community, mailbox)
        while not mission.ended and (args.count is None or printed < args.count):
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                break
            mail = mailbox.get(timeout=0.5 if remaining is None else min(0.5, remaining))
            if mail is None or mission.took(mail) or other_vehicle(args, mail.key):
                continue
            value, error = _decode_any(mail.key, mail.payload)
            if error:
                line = {"key": mail.key, "vehicle": vehicle_name(mail.key), "error": error}
            else:
                try:
                    line = {
                        "key": mail.key,
                        "vehicle": vehicle_name(mail.key),
                        "t": value.get("t") if isinstance(value, dict) else None,
                        "value": _project(value, args.field) if as_json else _for_people(mail.key, value, args.field),
                    }
                except KeyError as exc:
                    print(f"nearsub tap echo: {exc.args[0]} in {mail.key}", file=sys.stderr)
                    return 2
            print(json.dumps(line) if as_json else terminal_line(line), flush=True)
            printed += 1
    if args.count is not None and printed < args.count:
        when = f"before mission {community} ended" if mission.ended else f"within {args.timeout:g} s"
        print(f"nearsub tap echo: {printed} of {args.count} messages on {key} {when}", file=sys.stderr)
    elif mission.ended:
        print(f"nearsub tap echo: mission {community} ended", file=sys.stderr)
    return 0 if printed or args.count is None else 1


def terminal_line(line: dict) -> str:
    """One echoed message for people: its key, its simulated time to the millisecond, and its
    value as JSON with angles in degrees (`_for_people`; what `tap pub` takes), or the reason it
    could not be read."""
    t = line.get("t")
    when = f"t={t:.3f}" if isinstance(t, int | float) else "t=-"
    return f"{line['key']}  {when}  {json.dumps(line['value']) if 'value' in line else line['error']}"


def tap_watch(args) -> int:
    """The newest message on each key the key expressions match (uXMS): on a terminal a table
    refreshed four times a second, its columns the `--field`s (a field a message lacks is "-");
    piped or with --json, one JSON line per key at the end. It stops at Ctrl-C, --timeout or the
    mission end."""
    patterns = [topic_key(pattern, resolve_mission(args)) for pattern in args.keys]
    for pattern in patterns:
        check_key(pattern)
    bus, community = open_bus(args)
    from nearsub.common.runtime.bus import Mailbox

    live = not args.json and sys.stdout.isatty()
    latest: dict[str, dict] = {}  # key -> its row
    deadline = time.monotonic() + args.timeout if args.timeout else None
    with bus:
        if args.vehicle is not None:
            check_vehicle(args, publishing_vehicles(bus, community))
        mailbox = Mailbox()
        for pattern in patterns:
            bus.subscribe(pattern, mailbox)
        mission = MissionWatch(bus, community, mailbox)
        screen = _watch_screen(args.field, latest) if live else None
        try:
            while not mission.ended and (deadline is None or time.monotonic() < deadline):
                mail = mailbox.get(timeout=0.25)
                while mail is not None:
                    if not mission.took(mail) and not other_vehicle(args, mail.key):
                        latest[mail.key] = _watch_row(mail.key, mail.payload, args.field, live)
                    mail = mailbox.get(timeout=0)
                if screen is not None:
                    screen.update(_watch_table(args.field, latest))
        except KeyboardInterrupt:
            pass
        finally:
            if screen is not None:
                screen.stop()
    if not live:
        for key in sorted(latest):
            print(json.dumps(latest[key]))
    if not latest:
        print(f"nearsub tap watch: no message on {', '.join(patterns)}", file=sys.stderr)
        return 1
    return 0


def _watch_row(key: str, payload: bytes, fields: list[str] | None, people: bool) -> dict:
    """The newest message of a key: its value, or its `--field`s (None where it has none); for
    `people`, angles in degrees with their unit (`_for_people`)."""
    from nearsub.common.runtime.fields import for_people, people_name, people_unit

    value, error = _decode_any(key, payload)
    row = {"key": key, "vehicle": vehicle_name(key), "t": value.get("t") if isinstance(value, dict) else None}
    if error:
        return row | {"error": error}
    model = _model_name(key)
    shown = for_people(model, value) if people and isinstance(value, dict) else value
    if not fields:
        return row | {"value": shown}
    found, units = {}, {}
    for field in fields:
        try:
            found[field] = _field(shown, people_name(model, field) if people else field)
        except KeyError:
            found[field] = None  # another topic's field
        if people and (unit := people_unit(model, field)):
            units[field] = unit
    return row | {"fields": found} | ({"units": units} if units else {})


def _watch_table(fields: list[str] | None, latest: dict[str, dict]):
    from rich.table import Table

    table = Table("key", "t", *(fields or ["value"]), title="nearsub tap watch (Ctrl-C to stop)", title_justify="left")
    for key in sorted(latest):
        row = latest[key]
        t = row["t"]
        if "error" in row:
            cells = [row["error"]]
        elif fields:
            units = row.get("units", {})
            cells = [
                "-" if row["fields"][f] is None else f"{json.dumps(row['fields'][f])} {units.get(f, '')}".rstrip()
                for f in fields
            ]
        else:
            cells = [json.dumps(row["value"])]
        table.add_row(key, f"{t:.3f}" if isinstance(t, int | float) else "-", *cells)
    return table


def _watch_screen(fields: list[str] | None, latest: dict[str, dict]):
    from rich.live import Live

    from ..support import tables

    screen = Live(_watch_table(fields, latest), console=tables.console(), refresh_per_second=4)
    screen.start()
    return screen


def tap_hz(args) -> int:
    """Message rates per key, in simulated time (the message's t), like `ros2 topic hz`."""
    key = topic_key(args.key, resolve_mission(args))
    check_key(key)
    bus, community = open_bus(args)
    from nearsub.common.runtime.bus import Mailbox

    times: dict[str, deque] = defaultdict(lambda: deque(maxlen=args.window))
    with bus:
        if args.vehicle is not None:
            check_vehicle(args, publishing_vehicles(bus, community))
        deadline = time.monotonic() + args.duration
        next_report = time.monotonic() + 1.0
        mailbox = Mailbox()
        bus.subscribe(key, mailbox)
        while time.monotonic() < deadline:
            mail = mailbox.get(timeout=0.1)
            if mail is not None and not other_vehicle(args, mail.key):
                value, error = _decode_any(mail.key, mail.payload)
                if not error and isinstance(value, dict) and "t" in value:
                    times[mail.key].append(float(value["t"]))
            if time.monotonic() >= next_report or time.monotonic() >= deadline:
                next_report = time.monotonic() + 1.0
                _print_rates(times, args.json or not sys.stdout.isatty())
    if not times:
        print(f"nearsub tap hz: no message on {key} within {args.duration:g} s", file=sys.stderr)
        return 1
    return 0


def _print_rates(times, as_json: bool) -> None:
    for key, stamps in sorted(times.items()):
        span = stamps[-1] - stamps[0] if len(stamps) > 1 else 0.0
        hz = rate(stamps)
        if as_json:
            print(json.dumps({"key": key, "hz": hz, "samples": len(stamps), "sim_span": span}), flush=True)
        else:
            print(f"{key}: {hz:.2f} Hz (simulated time) over {len(stamps)} samples", flush=True)


# The clock's grants and ends and the apps' acks: one forged would let the apps run past the
# clock's pacing, or end a mission (docs/design.md, "The lock-step protocol").
LOCKSTEP_MESSAGES = ("Tick", "Ack", "MissionEnd")


def tap_pub(args) -> int:
    """Publish one message by hand (uPokeDB). It is validated against the topic's schema unless
    --no-validate; --raw-hex sends arbitrary bytes (for fault injection).

    On a vehicle topic only the operator's inputs are accepted (docs/design.md, "Steering a
    running mission"): a desired state, which the pid follows instead of the helm's, or an input,
    which the sim applies instead of the pid's, from the next step the consumer runs to the end of
    the mission or the next override. They go out with source "operator", and the command waits
    for the consumer's event that records the step. Other vehicle topics are refused (exit 2):
    their only accepted source is the app that computes them."""
    import msgpack

    from nearsub.common.runtime.fields import from_people
    from nearsub.common.runtime.lifecycle import OPERATOR, OPERATOR_TOPICS
    from nearsub.common.runtime.messages import VEHICLE_TOPICS, MessageError, decode, encode, model_for_key

    key = topic_key(args.key, resolve_mission(args))
    check_key(key)
    if "*" in key:
        raise InputError(f"key {args.key}: a message goes to one key; name the vehicle, e.g. VEHICLE/{args.key}")
    parts = key.split("/")
    leaf = parts[3] if len(parts) == 4 and parts[3] in VEHICLE_TOPICS else None
    operator = leaf in OPERATOR_TOPICS and args.raw_hex is None and not args.no_validate
    if args.raw_hex is not None:
        try:
            payload = bytes.fromhex(args.raw_hex)
        except ValueError:
            raise InputError(f"--raw-hex {args.raw_hex!r}: not hexadecimal bytes (two hex digits a byte)") from None
    else:
        try:
            fields = json.loads(args.value)
            packed = msgpack.packb(fields)  # what a message can carry: integers of 64 bits at most
        except json.JSONDecodeError as exc:
            print(f"nearsub tap pub: value is not JSON ({exc})", file=sys.stderr)
            return 2
        except RecursionError:
            raise InputError("value: JSON nested too deeply") from None
        except OverflowError:
            raise InputError(f"value {args.value[:60]!r}: an integer beyond 64 bits") from None
        if args.no_validate:
            payload = packed
        else:
            model = model_for_key(key)
            if model is None:
                print(f"nearsub tap pub: no message schema for key {key!r}", file=sys.stderr)
                return 2
            if not isinstance(fields, dict):
                raise InputError(f"value {args.value!r}: not a JSON object of fields")
            try:  # angles as people type them: NAME_deg in degrees (common/runtime/fields.py)
                fields = from_people(model.__name__, fields)
            except ValueError as exc:
                raise InputError(f"value: {exc}") from None
            fields = {"step": 0, "t": 0.0, "source": OPERATOR if operator else "tap", **fields}
            try:
                message = decode(msgpack.packb(fields), model, key)
            except MessageError as exc:
                print(f"nearsub tap pub: {exc}", file=sys.stderr)
                return 2
            if message.__class__.__name__ in LOCKSTEP_MESSAGES:
                raise InputError(
                    f"{key}: a {message.__class__.__name__} is the lock-step's own (the clock and the apps "
                    "publish it); --no-validate sends it anyway, for fault injection"
                )
            if leaf is not None and not operator:
                print(
                    f"nearsub tap pub: {leaf} is accepted only from the app that computes it; an operator may "
                    f"set {' or '.join(OPERATOR_TOPICS)} (docs/design.md, 'Steering a running mission')",
                    file=sys.stderr,
                )
                return 2
            if operator and message.source != OPERATOR:
                print(f"nearsub tap pub: an operator's {leaf} goes out with source {OPERATOR!r}", file=sys.stderr)
                return 2
            payload = encode(message)
    bus, _ = open_bus(args)
    from nearsub.common.runtime.bus import Mailbox

    vehicle = vehicle_name(key) if leaf is not None else None
    from nearsub.common.runtime import keys

    with bus:
        mailbox = Mailbox()
        if operator:
            # The logger hears every key, so an override for a vehicle nobody flies would be
            # "delivered" and wait for a confirmation that never comes: name it at once instead.
            running = publishing_vehicles(bus, parts[1])
            if running and vehicle not in running:
                raise InputError(f"no vehicle {vehicle!r} in mission {parts[1]!r} (its vehicles: {', '.join(running)})")
            # The consumer's event: from a mission-wide app instance, or one of the vehicle's.
            bus.subscribe(keys.all_events(parts[1]), mailbox)
        # A fresh session drops data put before it knows a subscriber (docs/design.md, "Transport").
        if not bus.put_when_matched(key, payload, wait=5.0):
            if operator:
                running = publishing_vehicles(bus, parts[1])
                print(
                    f"nearsub tap pub: nobody consumes {key}: is vehicle {vehicle!r} running? "
                    f"(vehicles publishing: {', '.join(running) or 'none'})",
                    file=sys.stderr,
                )
                return 1
            print(f"nearsub tap pub: nobody subscribes to {key}; published anyway", file=sys.stderr)
        if operator:
            return _confirm_override(mailbox, leaf, vehicle)
        time.sleep(0.1)  # let the session flush before it closes
    return 0


def _confirm_override(mailbox, leaf: str, vehicle: str, timeout: float = 10.0) -> int:
    """Wait for the consumer's event recording the override; print the vehicle, the app and the step."""
    from nearsub.common.runtime.messages import Event, MessageError, decode

    end = time.monotonic() + timeout
    while (remaining := end - time.monotonic()) > 0:
        mail = mailbox.get(timeout=remaining)
        if mail is None:
            break
        try:
            event = decode(mail.payload, Event, mail.key)
        except MessageError:
            continue
        mine = vehicle_name(mail.key) in (None, vehicle)  # another vehicle's app confirms another override
        if mine and event.kind == "info" and event.data.get("leaf") == leaf and event.detail.startswith("operator"):
            print(f"{vehicle}/{event.source}: {event.detail}")
            return 0
    print(f"nearsub: no app confirmed the {leaf} override within {timeout:g} s", file=sys.stderr)
    return 1

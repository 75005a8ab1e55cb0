"""`nearsub swap`, as the launcher answers it on its control key: pause the clock at a step
boundary (or at the step asked), start the new app instance, which takes over the old one's
progress and inputs, retire the old one, resume. `launcher` is the running
`supervision.Launcher`."""

from __future__ import annotations

import msgpack

from nearsub.common.mission.schema import Mission, MissionError, apply_overrides, mission_from_dict
from nearsub.common.runtime import keys
from nearsub.common.runtime.lifecycle import ORDER
from nearsub.common.runtime.processes import stop

from .processes import LaunchError


class SwapRefused(LaunchError):
    """A swap request that is wrong in itself (the app, the vehicle, a setting): refused before the
    clock pauses, and answered as bad input (`nearsub swap` exits 2)."""


def answer(launcher, mail) -> None:
    """Answer one control request (a msgpack map with 'cmd'; only "swap" is known)."""
    try:
        request = msgpack.unpackb(mail.payload)
        command = request["cmd"]
    except Exception:
        mail.reply_error("launcher: control request is not a msgpack map with 'cmd'")
        return
    if command != "swap":
        mail.reply_error(f"launcher: unknown command {command!r}")
        return
    try:
        at = request.get("at_step")
        vehicle = request.get("vehicle")
        result = swap(
            launcher,
            str(request.get("app", "")),
            list(request.get("set", [])),
            None if at is None else int(at),
            None if vehicle is None else str(vehicle),
        )
    except SwapRefused as exc:
        mail.reply(msgpack.packb({"ok": False, "refused": str(exc)}))
        return
    except LaunchError as exc:
        mail.reply_error(str(exc))
        return
    mail.reply(msgpack.packb(result))


def swap(launcher, role: str, overrides: list[str], at_step: int | None = None, vehicle: str | None = None) -> dict:
    """Replace `role` (of `vehicle`, which a mission of several vehicles needs) at a step boundary."""
    mission, processes = launcher.mission, launcher.processes
    if role not in ORDER:
        raise SwapRefused(f"cannot swap {role!r}: only {', '.join(ORDER)} can be swapped")
    vehicle = swapped_vehicle(mission, vehicle)
    app = keys.app_name(vehicle, role)
    old = next(
        (c for c in processes.children.values() if c.role == app and not c.retiring and c.process.poll() is None),
        None,
    )
    if old is None:
        raise SwapRefused(f"no running {app} to swap")
    prefixed = [o if o.startswith("apps.") else f"apps.{role}.{o}" for o in overrides]
    if vehicle is not None:  # that vehicle's own settings
        prefixed = [f"vehicles.{vehicle}.{o}" for o in prefixed]
    try:
        mission_from_dict(apply_overrides(mission.model_dump(mode="json"), prefixed), "--with")
    except MissionError as exc:
        raise SwapRefused(str(exc)) from None
    caller = launcher.caller
    wait = mission.step_timeout + 5
    if at_step is not None:
        wait += 600.0  # the clock answers when it reaches the step
    paused = caller.call("clock", "pause", timeout=wait, **({} if at_step is None else {"at": at_step}))
    if paused is None:
        raise LaunchError("the clock did not pause")
    if not paused.ok:
        raise LaunchError(paused.error)
    step = int(paused.data["step"])
    instance = processes.next_instance(app)
    extra = ["--takeover", old.instance, "--resume-step", str(step)]
    for override in prefixed:
        extra += ["--set", override]
    if vehicle is not None:
        extra += ["--vehicle", vehicle]
    new = processes.spawn(role, instance, app, extra)
    try:
        processes.wait_alive(
            launcher.bus, mission.name, [(app, instance)], mission.startup_timeout, launcher.interrupted
        )
    except LaunchError:
        stop([new.process], grace=0.0)
        new.retiring = True
        caller.call("clock", "resume", timeout=5.0)
        raise
    old.retiring = True
    caller.call(old.instance, "retire", timeout=5.0)
    stop([old.process], grace=5.0)
    detail = f"{old.instance} -> {instance} at step {step}" + (f" with {', '.join(prefixed)}" if prefixed else "")
    launcher.publish_event("swap", detail, step, {"old": old.instance, "new": instance, "step": step, "set": prefixed})
    launcher.summary.swaps.append({"old": old.instance, "new": instance, "step": step})
    caller.call("clock", "resume", timeout=5.0)
    return {"ok": True, "old": old.instance, "new": instance, "step": step}


def swapped_vehicle(mission: Mission, vehicle: str | None) -> str | None:
    """The vehicle a swap serves: the one named, the only one, or None without [[vehicles]]."""
    names = mission.vehicle_names
    if not mission.fleet:
        if vehicle is not None:
            raise SwapRefused(f"vehicle {vehicle!r}: mission {mission.name!r} has no [[vehicles]]")
        return None
    if vehicle is None and len(names) > 1:
        raise SwapRefused(f"mission {mission.name!r} has several vehicles ({', '.join(names)}): name one")
    if vehicle is not None and vehicle not in names:
        raise SwapRefused(f"no vehicle named {vehicle!r} (the mission's vehicles: {', '.join(names)})")
    return vehicle or names[0]

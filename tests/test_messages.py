import math

import msgpack
import pytest
from pydantic import BaseModel

from nearsub.common.runtime.messages import (
    ALL_MODELS,
    Control,
    Event,
    Forces,
    HelmProgress,
    Input,
    MessageError,
    State,
    decode,
    encode,
    model_for_key,
)


def state(**overrides):
    fields = dict(step=3, t=0.15, source="sim", u=1.2, v=0.0, r=0.01, x=1.0, y=-2.0, psi=0.5)
    fields.update(overrides)
    return State(**fields)


def test_round_trip_is_exact():
    message = state(u=1 / 3, psi=math.pi / 7)
    assert decode(encode(message), State) == message


def test_nan_is_rejected_naming_the_field():
    payload = msgpack.packb({**state().model_dump(), "u": float("nan")})
    with pytest.raises(MessageError) as info:
        decode(payload, State, "nearsub/a/remus100/state")
    text = str(info.value)
    assert "nearsub/a/remus100/state" in text and "'u'" in text and "nan" in text


def test_missing_and_unknown_fields_are_named():
    data = state().model_dump()
    del data["psi"]
    data["warp_drive"] = 9
    with pytest.raises(MessageError) as info:
        decode(msgpack.packb(data), State)
    assert "'psi'" in str(info.value) and "'warp_drive'" in str(info.value)


def test_absurd_rudder_is_rejected():
    payload = msgpack.packb({"step": 0, "t": 0.0, "source": "pid", "X_prop": 1.0, "delta_r": 1e9})
    with pytest.raises(MessageError, match="delta_r"):
        decode(payload, Input)


def test_garbage_bytes_are_a_message_error():
    with pytest.raises(MessageError, match="not valid msgpack"):
        decode(b"\xc1\xff\x00", State)
    with pytest.raises(MessageError, match="expected a map"):
        decode(msgpack.packb([1, 2, 3]), State)


def test_unknown_schema_version_is_rejected():
    payload = msgpack.packb({**state().model_dump(), "schema_version": 99})
    with pytest.raises(MessageError, match="schema_version"):
        decode(payload, State)


def test_models_for_keys():
    assert model_for_key("nearsub/a/remus100/state") is State
    assert model_for_key("nearsub/a/remus100/input") is Input
    assert model_for_key("elsewhere/a/b") is None


def test_encode_writes_the_bytes_of_model_dump_for_every_kind_of_message():
    """`encode` packs the model's fields as they are: right only while no field holds a model."""
    for model in ALL_MODELS:
        for name, info in model.model_fields.items():
            assert "BaseModel" not in repr(info.annotation), (model.__name__, name)
            assert not (isinstance(info.annotation, type) and issubclass(info.annotation, BaseModel))
    made = [
        state(),
        State.model_construct(**state().model_dump()),
        state().model_copy(update={"x": 7.0}),
        HelmProgress(
            step=5,
            t=0.25,
            behaviour="waypoints",
            leg=0,
            waypoint_index=1,
            waypoints_reached=0,
            psi_d=0.1,
            active=["survey"],
        ),
        Forces(
            step=1,
            t=0.05,
            X_s=1.0,
            Y_s=2.0,
            N_s=3.0,
            std_X=0.1,
            std_Y=0.1,
            std_N=0.1,
            weight=1.0,
            in_domain=True,
            constraints_ok=False,
            outside=["psi"],
        ),
        Event(step=2, t=0.1, kind="info", detail="d", data={"a": [1, 2.5], "b": {"c": None}}),
        Control(step=0, t=0.0, cmd="pause", args={"at": 3}, request_id="r", reply_to="tool"),
    ]
    for message in made:
        assert encode(message) == msgpack.packb(message.model_dump(mode="python"), use_bin_type=True)
        assert encode(decode(encode(message), type(message))) == encode(message)  # (NaN defaults: bytes, not ==)

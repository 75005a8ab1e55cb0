import math

import msgpack
import pytest

from nearsub.common.runtime.messages import Input, MessageError, State, decode, encode, model_for_key


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

"""`nearsub.logs`: a DataFrame per topic in one call, and a decoder factory for the `mcap` reader."""

import math
import sys

import pytest
from logsample import write_sample_log
from mcap.reader import make_reader

from nearsub.logs import PANDAS_MISSING, DecoderFactory, read_frames, read_messages, read_metadata


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    path = tmp_path_factory.mktemp("frames") / "alpha.mcap"
    return path, write_sample_log(path, shuffle=True)


def test_one_frame_per_topic_in_log_time_order(log):
    path, result = log
    frames = read_frames(path)
    assert "nearsub/alpha/remus100/state" in frames and "nearsub/alpha/control/clock" in frames
    assert not any(topic.endswith("#invalid") for topic in frames)
    state = frames["nearsub/alpha/remus100/state"]
    states = sorted(result.topic("state"), key=lambda s: s.step)
    assert len(state) == len(states)
    assert list(state.columns[:5]) == ["log_time", "schema_version", "step", "t", "source"]
    assert state["log_time"].is_monotonic_increasing
    assert state["x"].tolist() == [s.x for s in states] and state["psi"].tolist() == [s.psi for s in states]
    assert state["step"].tolist() == [s.step for s in states]
    inputs = frames["nearsub/alpha/remus100/input"]
    assert inputs["delta_r"].tolist() == [m.delta_r for m in sorted(result.topic("input"), key=lambda m: m.step)]


def test_nested_fields_are_flattened(log):
    path, result = log
    frames = read_frames(path, topics="nearsub/alpha/events/**")
    assert set(frames) == {"nearsub/alpha/events/helm", "nearsub/alpha/events/pid"}
    strays = sorted((e for e in result.topic("events") if e.kind == "large_stray"), key=lambda e: e.step)
    assert strays, "the sample run strays from its track-line in its first seconds"
    helm = frames["nearsub/alpha/events/helm"]
    rows = helm[helm["kind"] == "large_stray"]
    assert rows["data.cross_track"].tolist() == [e.data["cross_track"] for e in strays]
    assert "data" not in frames["nearsub/alpha/events/pid"].columns  # an empty map gives no column


def test_topics_take_key_expressions(log):
    path, _ = log
    assert set(read_frames(path, topics="nearsub/alpha/*/state")) == {"nearsub/alpha/remus100/state"}
    assert set(read_frames(path, topics=["nearsub/alpha/remus100/desired", "nearsub/alpha/control/*"])) == {
        "nearsub/alpha/remus100/desired",
        "nearsub/alpha/control/clock",
    }
    with pytest.raises(ValueError, match="topics 'nearsub//state': not a key expression"):
        read_frames(path, topics="nearsub//state")


def test_read_messages_without_pandas_and_invalid_payloads(log, monkeypatch):
    path, result = log
    monkeypatch.setitem(sys.modules, "pandas", None)  # as if pandas were not installed
    with pytest.raises(ModuleNotFoundError) as missing:
        read_frames(path)
    assert str(missing.value) == PANDAS_MISSING and "pip install 'nearsub[pandas]'" in PANDAS_MISSING
    messages = list(read_messages(path, topics="nearsub/alpha/remus100/state", invalid=True))
    assert len(messages) == len(result.topic("state")) + 1
    assert messages[-1] == ("nearsub/alpha/remus100/state#invalid", 10.0, b"\xc1")
    assert [t for _, t, _ in messages] == sorted(t for _, t, _ in messages)


def test_decoder_factory_for_the_mcap_reader(log):
    path, result = log
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        decoded = [(channel.topic, value) for _, channel, _, value in reader.iter_decoded_messages()]
    desired = [value for topic, value in decoded if topic == "nearsub/alpha/remus100/desired"]
    assert [d["psi_d"] for d in desired] == [d.psi_d for d in sorted(result.topic("desired"), key=lambda d: d.step)]
    assert ("nearsub/alpha/remus100/state#invalid", b"\xc1") in decoded


def test_metadata_with_the_resolved_mission(log):
    path, _ = log
    metadata = read_metadata(path)
    assert metadata["mission"]["name"] == "alpha"
    assert math.isclose(metadata["mission"]["resolved"]["dt"], 0.05)

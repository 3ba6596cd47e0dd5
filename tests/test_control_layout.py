"""The Open Stage Control layout (clients/openstagecontrol/performer.json, docs/show.md) against the
engine: every value each widget can send, sent over real UDP to the OSC control input of an engine
with the shipped model, is applied (none refused), and the engine reads it back (realtime/controls.py)."""

from __future__ import annotations

import json
import socket
import time
from pathlib import Path

import pytest

from realtime.osc_control import ADDRESSES, OscControl
from realtime.vmc import osc_message

LAYOUT = Path(__file__).resolve().parents[1] / "clients" / "openstagecontrol" / "performer.json"


def widget_messages(widget: dict) -> list[tuple[str, object]]:
    """(address, value) for every value the widget sends: a fader's ends and default, a switch's or
    dropdown's values, a button's on and off."""
    kind, address = widget["type"], widget["address"]
    if kind == "fader":
        return [(address, float(v)) for v in (widget["range"]["min"], widget["range"]["max"], widget["default"])]
    if kind in ("switch", "dropdown"):
        return [(address, v) for v in widget["values"].values()]
    assert kind == "button", kind
    return [(address, int(widget["on"])), (address, int(widget["off"]))]


@pytest.fixture(scope="module")
def engine():
    from realtime.audio_input import FileSource
    from realtime.engine import Engine
    from realtime.pipeline import build_pipeline
    from models.features.audio_io import bundled_clip_path

    pipe = build_pipeline(None, seed=0)
    return Engine(FileSource.open(bundled_clip_path()), pipe.extractor_factory, pipe.model)


def test_every_widget_of_the_layout_is_a_control_the_engine_applies(engine):
    session = json.loads(LAYOUT.read_text())
    widgets = session["content"]["widgets"]
    assert session["type"] == "session" and {w["address"] for w in widgets} <= set(ADDRESSES)
    sent = [m for w in widgets for m in widget_messages(w)]
    assert {a for a, _ in sent} == set(ADDRESSES) - {"/performer/offset", "/performer/smoothing"}
    with OscControl("127.0.0.1", 0, control=engine.control) as control, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
        control.start()
        applied = []
        for address, value in sent:
            udp.sendto(osc_message(address, value), ("127.0.0.1", control.port))
            deadline = time.monotonic() + 5
            while control.stats()["messages"] < len(applied) + 1 and time.monotonic() < deadline:
                time.sleep(0.01)
            applied.append(engine.applied()["performer"])
        stats = control.stats()
    assert stats["bad"] == 0 and stats["messages"] == len(sent), stats
    # the engine read back what each one set (the last message to each address wins)
    last = {a: v for a, v in sent}
    now = engine.applied()["performer"]
    assert now["energy"] == last["/performer/energy"] and now["lead_ms"] == last["/performer/lead"]
    assert now["style"] == last["/performer/style"] and now["facing"] == last["/performer/facing"]
    assert now["idle"] is bool(last["/performer/idle"])
    assert applied[[a for a, _ in sent].index("/performer/energy") + 1]["energy"] == 2.0  # the fader's top applied

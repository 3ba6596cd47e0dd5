"""The web viewer through a NATS broker in a real Chromium: ``performer run --publish`` -> a
real nats-server -> its WebSocket port -> clients/web with ``?broker=`` (docs/audience.md)."""

from __future__ import annotations

import os

import numpy as np
import pytest
from test_run_cli import clip, tiny_checkpoint  # noqa: F401 - fixtures
from test_web_client import browser, open_page, performer_run  # noqa: F401 - fixtures

from models.rig.humanoid import NUM_BONES
from realtime.nats_server import PUBLISHER, VIEWER, LocalBroker, find_nats_server

pytestmark = pytest.mark.skipif(find_nats_server() is None,
                                reason="nats-server is not installed (apt-get install nats-server; make setup)")


@pytest.fixture
def published_show(tmp_path, clip, tiny_checkpoint):  # noqa: F811 - fixtures from test_run_cli
    """A broker, and ``performer run`` publishing the clip to it (its own server serves the page)."""
    env = {**os.environ, "PERFORMER_PUBLISH_USER": PUBLISHER[0], "PERFORMER_PUBLISH_PASSWORD": PUBLISHER[1]}
    with LocalBroker(tmp_path) as broker, performer_run(
            tmp_path, ["--audio", str(clip), "--no-osc", "--checkpoint", str(tiny_checkpoint), "--warmup", "0.5",
                       "--quiet", "--publish", broker.url], env=env) as url:
        yield url, broker


@pytest.mark.slow
def test_the_viewer_through_the_broker_shows_the_avatar_moving_frames_in_order(published_show, open_page):
    url, broker = published_show
    page = open_page(f"{url}?broker={broker.ws_url}&subject=performer.main&user={VIEWER[0]}&pass={VIEWER[1]}")
    first = page.wait_for(lambda s: s["state"] == "open" and s["framesReceived"] >= 10)
    assert first["source"] == "broker" and broker.ws_url in first["url"] and "performer.main" in first["url"]
    assert first["bones"] == NUM_BONES and first["avatar"] == "procedural"
    assert page.page.inner_text("#source") == "broker"
    q1 = page.page.evaluate("window.performer.boneQuaternion('LeftUpperArm')")
    second = page.wait_for(lambda s: s["framesReceived"] >= first["framesReceived"] + 45)
    q2 = page.page.evaluate("window.performer.boneQuaternion('LeftUpperArm')")
    assert abs(np.linalg.norm(q2) - 1) < 1e-3 and not np.allclose(q1, q2, atol=1e-4)  # it moved
    got = second["framesReceived"] - first["framesReceived"]
    assert second["lastIndex"] - first["lastIndex"] == got + second["dropped"] - first["dropped"]
    # In order: never a step back; on loopback the broker loses none (a slow consumer would show here).
    assert second["restarts"] == 0 and second["dropped"] == 0 and second["badFrames"] == 0
    assert not page.errors, page.errors


@pytest.mark.slow
def test_the_viewer_without_broker_says_performer_run(published_show, open_page):
    url, _ = published_show
    page = open_page(url)
    s = page.wait_for(lambda s: s["state"] == "open" and s["framesReceived"] >= 5)
    assert s["source"] == "performer run" and page.page.inner_text("#source") == "performer run"

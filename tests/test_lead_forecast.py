"""The lead's beat forecast (models/networks/lead.py; docs/listening.md, "Lead")."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from models.features.context import ContextTracker
from models.networks.lead import PhaseForecast

REPO = Path(__file__).resolve().parents[1]


def test_the_forecast_is_the_trackers_phase_lead_frames_on_when_the_onsets_repeat_a_period_back():
    """Where the next L onsets are those one period P earlier, the forecast made before hearing
    them is the tracker's own phase L frames on; a rotation by 2 pi L / P of the phase of now
    is not, the newest onsets weighing most in the tracker's window."""
    rng = np.random.default_rng(3)
    period, t = 15, 400
    onset = rng.random(t + 8) * (np.arange(t + 8) % 5 == 0)  # irregular onsets
    tracker = ContextTracker(1, 0.0, True)
    for lead in (2, 4, 6):
        x = onset.copy()
        x[t + 1: t + 1 + lead] = x[t + 1 - period: t + 1 - period + lead]
        tracker.reset()
        cols = tracker(x[:, None])
        truth = math.atan2(cols[t + lead, 1], cols[t + lead, 0])
        f = PhaseForecast()
        for v in x[: t + 1]:
            f.push(float(v))
        assert abs(math.remainder(f.phase(lead, float(period)) - truth, 2 * math.pi)) < 1e-6
        now = math.atan2(cols[t, 1], cols[t, 0])
        assert abs(math.remainder(now + 2 * math.pi * lead / period - truth, 2 * math.pi)) > 0.02
    f.reset()
    assert f.phase(4, float("nan")) == 0.0  # nothing heard: no phase (and no bad period read)


def test_the_streams_lead_reads_the_phase_lead_0_will_read_when_the_music_goes_on_as_it_went():
    """The shipped model on the repository's clip: where the next 4 onsets are those one tracker
    period back, the beat phase a stream with a 133-ms lead dances to at frame t is the one a
    lead-0 stream dances to at t + 4 (the phase rotated by 2 pi L / P misses it by up to 0.018
    of a beat); the lead's forecast switched off (``ONSET_FORECAST``), it does not hold."""
    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model
    from models.networks import lead as lead_part
    from models.networks.dance_stream import DanceStream

    lm = load_model(str(REPO / "models" / "assets" / "default.pt"))
    m, lead = lm.model, 4
    feats = extract_features(load_audio(REPO / "models" / "assets" / "clip.ogg", 22050)[0], lm.features)
    oc, cc = m.config.onset_col, m.config.clarity_col
    misses = {True: [], False: []}
    for t in (400, 600, 700):
        x = feats[: t + lead + 1].copy()
        on = x[:, oc].astype(np.float64)
        period = 15.0 * 2.0 ** float(x[t, cc + 1])
        for k in range(1, lead + 1):  # the music goes on as it went: an onset one period back
            i, f = int(math.floor(t + k - period)), (t + k - period) % 1.0
            on[t + k] = (1.0 - f) * on[i] + f * on[i + 1]
        x[:, oc] = on
        x[:, cc - 2: cc + 2] = ContextTracker(1, 0.0, True)(x[:, oc: oc + 1].astype(np.float64))  # its beat columns
        later = DanceStream(m)
        later.push(x)
        shipped = lead_part.ONSET_FORECAST
        for forecast in (True, False):  # as shipped, then the rotation beside it
            lead_part.ONSET_FORECAST = shipped and forecast
            try:
                s = DanceStream(m, lead_ms=133.0)
                s.push(x[: t + 1])
            finally:
                lead_part.ONSET_FORECAST = shipped
            misses[forecast].append(abs(math.remainder(s.beat_phase - later.beat_phase, 1.0)))
    assert max(misses[True]) < 1e-3
    assert max(misses[False]) > 5e-3  # the rotation's forecast: a real difference

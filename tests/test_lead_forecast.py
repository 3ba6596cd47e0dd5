"""The lead's beat forecast (models/networks/lead.py; docs/listening.md, "Lead")."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

import pytest

from models.features.context import ContextTracker
from models.networks import lead as lead_part
from models.networks.lead import PhaseForecast

REPO = Path(__file__).resolve().parents[1]


def _forecasts(onset: np.ndarray, period: np.ndarray, arms: dict[str, dict]) -> dict[str, np.ndarray]:
    """Per arm (module settings of models/networks/lead.py, e.g. ``{"RUNNER_UP": False}``), the
    forecast phases (radians, 4 frames on) read every frame of ``onset`` (T,) under the tracker's
    ``period`` (T,, frames), the frames 0..T-5; the settings are restored after."""
    shipped = {k: getattr(lead_part, k) for arm in arms.values() for k in arm}
    out = {}
    try:
        for key, arm in arms.items():
            for k, v in {**shipped, **arm}.items():
                setattr(lead_part, k, v)
            f, out[key] = PhaseForecast(), []
            for t in range(len(onset) - 4):
                f.push(float(onset[t]))
                out[key].append(f.phase(4, float(period[t])))
    finally:
        for k, v in shipped.items():
            setattr(lead_part, k, v)
    return {k: np.array(v) for k, v in out.items()}


def test_the_forecast_is_the_trackers_phase_lead_frames_on_when_the_onsets_repeat_a_period_back():
    """Where the next L onsets are those one period P earlier, the forecast made before hearing
    them is the tracker's own phase L frames on; a rotation by 2 pi L / P of the phase of now is
    not, the newest onsets weighing most in the tracker's window."""
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


@pytest.mark.parametrize("periods", [(22, 12, 0.6), (27, 15, 0.6)])
def test_where_the_tracker_changes_level_within_the_lead_the_forecast_changes_with_it(periods):
    """Two pulses of onsets nearly an octave apart (every a frames, strength 1; every b, s), the
    tracker's level changing between them as one or the other's onsets arrive (brahms:
    docs/listening.md, "Lead").
    At the frames whose next 4 onsets change it, the forecast, which reads where the runner-up
    period's expected onsets change the level, reads the phase the tracker will read 4 frames on
    (median miss < 0.01 rad); expecting those one tracker period back only (``RUNNER_UP`` off)
    misses by over 1 rad."""
    a, b, strength = periods
    n = np.arange(700)
    onset = np.maximum((n % a == 3) * 1.0, (n % b == 7) * strength)
    cols = ContextTracker(1, 0.0, True)(onset[:, None])
    period = 15.0 * 2.0 ** cols[:, 3]
    lead, shipped = 4, lead_part.RUNNER_UP
    flips = [t for t in range(200, 696) if abs(math.log2(period[t + lead] / period[t])) > 0.1]
    assert len(flips) > 50  # the level changes over and over
    misses = {}
    try:
        for runner_up in (True, False):
            lead_part.RUNNER_UP = shipped and runner_up
            f, miss = PhaseForecast(), []
            for t in range(696):
                f.push(float(onset[t]))
                a = f.phase(lead, float(period[t]))  # every frame, as the stream reads it
                if t in flips:
                    miss.append(abs(math.remainder(a - math.atan2(cols[t + lead, 1], cols[t + lead, 0]), 2 * math.pi)))
            misses[runner_up] = float(np.median(miss))
    finally:
        lead_part.RUNNER_UP = shipped
    assert misses[True] < 0.01
    assert misses[False] > 1.0


@pytest.mark.parametrize("periods", [(21, 14), (20, 15)])
def test_a_change_of_level_by_less_than_an_octave_is_not_forecast(periods):
    """Two pulses of onsets a fifth or a fourth apart (every a frames, strength 1; every b, 0.8;
    3:2 and 4:3), the tracker's level changing between them over and over (DANCE_R_5: 17 <-> 11
    frames, where forecasting those changes cost the lead hits: docs/listening.md, "Lead"). The
    forecast is the one expecting the onsets one tracker period back only at every frame
    (``RUNNER_UP_CHANGE``); taking the runner-up's level at any change (0), it differs by over
    1 rad at the frames whose next 4 onsets change the level."""
    a, b = periods
    n = np.arange(700)
    onset = np.maximum((n % a == 3) * 1.0, (n % b == 7) * 0.8)
    period = 15.0 * 2.0 ** ContextTracker(1, 0.0, True)(onset[:, None])[:, 3].astype(np.float64)
    flips = [t for t in range(200, 696) if abs(math.log2(period[t + 4] / period[t])) > 0.1]
    assert len(flips) > 50  # the level changes over and over, by under an octave
    assert all(abs(math.log2(period[t + 4] / period[t])) < 0.75 for t in flips)
    phases = _forecasts(onset, period, {"period": {"RUNNER_UP": False}, "shipped": {}, "any": {"RUNNER_UP_CHANGE": 0.0}})
    miss = {k: np.abs(np.remainder(v - phases["period"] + np.pi, 2 * np.pi) - np.pi) for k, v in phases.items()}
    assert miss["shipped"].max() == 0.0
    assert np.median(miss["any"][flips]) > 1.0


@pytest.mark.parametrize("periods", [(23, 12, 0.8), (25, 12, 0.7), (19, 10, 0.6)])
def test_on_a_steady_level_the_forecast_is_the_periods_alone(periods):
    """Two pulses (every a frames, strength 1; every b, strength s) under which the tracker holds one
    level from frame 150 on: from frame 200 the forecast is the one expecting the onsets one
    tracker period back only; read whatever the level's steadiness (``UNSTEADY_FRAMES`` off),
    the runner-up's expected onsets forecast a level an octave off that the tracker never takes
    (by over 2 rad)."""
    a, b, strength = periods
    n = np.arange(700)
    onset = np.maximum((n % a == 3) * 1.0, (n % b == 7) * strength)
    period = 15.0 * 2.0 ** ContextTracker(1, 0.0, True)(onset[:, None])[:, 3].astype(np.float64)
    assert not np.any(np.abs(np.diff(np.log2(period[150:]))) > lead_part.LEVEL_CHANGE)
    off = _forecasts(onset, period, {"period": {"RUNNER_UP": False}, "shipped": {},
                                     "ungated": {"RUNNER_UP": True, "UNSTEADY_FRAMES": 1 << 40}})
    miss = {k: np.abs(np.remainder(v[200:] - off["period"][200:] + np.pi, 2 * np.pi) - np.pi).max() for k, v in off.items()}
    assert miss["shipped"] == 0.0
    assert miss["ungated"] > 2.0


def test_the_streams_lead_reads_the_phase_lead_0_will_read_when_the_music_goes_on_as_it_went():
    """The shipped model on the repository's clip: where the next 4 onsets are those one tracker
    period back, the beat phase a stream with a 133-ms lead dances to at frame t is the one a
    lead-0 stream dances to at t + 4 (the clip's level steady: as with the onsets one period back
    only, ``RUNNER_UP`` off), where the phase rotated by 2 pi L / P (``ONSET_FORECAST`` off) misses
    it by up to 0.018 of a beat."""
    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model
    from models.networks.dance_stream import DanceStream

    lm = load_model(str(REPO / "models" / "assets" / "default.pt"))
    m, lead = lm.model, 4
    feats = extract_features(load_audio(REPO / "models" / "assets" / "clip.ogg", 22050)[0], lm.features)
    oc, cc = m.config.onset_col, m.config.clarity_col
    modes = {"period": (True, False), "rotation": (False, False), "shipped": (True, True)}
    misses = {k: [] for k in modes}
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
        shipped = lead_part.ONSET_FORECAST, lead_part.RUNNER_UP
        for mode, (forecast, runner_up) in modes.items():
            lead_part.ONSET_FORECAST, lead_part.RUNNER_UP = shipped[0] and forecast, shipped[1] and runner_up
            try:
                s = DanceStream(m, lead_ms=133.0)
                s.push(x[: t + 1])
            finally:
                lead_part.ONSET_FORECAST, lead_part.RUNNER_UP = shipped
            misses[mode].append(abs(math.remainder(s.beat_phase - later.beat_phase, 1.0)))
    assert max(misses["period"]) < 1e-3
    assert max(misses["shipped"]) < 1e-3
    assert max(misses["rotation"]) > 5e-3  # the rotation's forecast: a real difference


def test_a_streams_lead_changes_level_with_the_tracker_where_lead_0_will():
    """The shipped model on two pulses of onsets (every 22 frames and every 12, strength 1 and 0.6,
    the clip's other feature columns under them): at the frames whose next 4 onsets change the
    tracker's level (by 0.87 octave), the beat phase a 133-ms lead dances to at frame t is the one
    lead 0 dances to at t + 4 (median miss < 0.005 of a beat; 0.12 were the forecast's period not
    passed on with its phase); expecting the onsets one tracker period back only (``RUNNER_UP``
    off), it misses by over 0.1 (0.35)."""
    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model
    from models.networks.dance_stream import DanceStream

    lm = load_model(str(REPO / "models" / "assets" / "default.pt"))
    m, lead = lm.model, 4
    x = extract_features(load_audio(REPO / "models" / "assets" / "clip.ogg", 22050)[0], lm.features)[:500].copy()
    oc, cc = m.config.onset_col, m.config.clarity_col
    n = np.arange(len(x))
    x[:, oc] = np.maximum((n % 22 == 3) * 1.0, (n % 12 == 7) * 0.6) * float(np.percentile(x[:, oc], 99))
    x[:, cc - 2: cc + 2] = ContextTracker(1, 0.0, True)(x[:, oc: oc + 1].astype(np.float64))
    period = 15.0 * 2.0 ** x[:, cc + 1].astype(np.float64)
    flips = {t for t in range(240, len(x) - lead) if abs(math.log2(period[t + lead] / period[t])) > 0.1}
    assert len(flips) > 20
    later, phase0 = DanceStream(m), {}
    for t in range(len(x)):
        later.push(x[t: t + 1])
        phase0[t] = later.beat_phase
    misses, shipped = {}, lead_part.RUNNER_UP
    try:
        for runner_up in (True, False):
            lead_part.RUNNER_UP = shipped and runner_up
            s, miss = DanceStream(m, lead_ms=133.0), []
            for t in range(len(x) - lead):
                s.push(x[t: t + 1])
                if t in flips:
                    miss.append(abs(math.remainder(s.beat_phase - phase0[t + lead], 1.0)))
            misses[runner_up] = float(np.median(miss))
    finally:
        lead_part.RUNNER_UP = shipped
    assert misses[True] < 0.005
    assert misses[False] > 0.1

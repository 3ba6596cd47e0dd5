"""Fit the idle gate's music presence detector (:mod:`models.networks.music_gate`).

The detector must say "music" on every genre and "not music" on silence, applause, crowd,
room noise and speech. The training songs are three ballroom styles only, so it also learns
from material generated here, at the levels a microphone or desk feed gives between songs:

* **electronic music** (:func:`electronic`): drum-machine patterns (kick, snare or clap,
  hats: four-on-the-floor, breakbeat, half-time) at 120-190 bpm, saw or square bass,
  detuned-saw pads pumped by a sidechain, arpeggiated leads, breakdowns without drums,
  sparse drums-and-bass passages, reverberation;
* **other music** (:func:`tonal`): piano-like and plucked notes, bowed-string pads with
  vibrato, simple rock drums under distorted chords, at 60-160 bpm, in a room;
* **speech** (:func:`speech`): Debian's ``espeak-ng`` (apt package ``espeak-ng``), many
  voices, rates and pitches, with pauses, room reverberation, a noise bed, at -35 to -10 dBFS;
* **crowd** (babble of 6-30 of those voices, -30 to -45 dBFS), **applause** (20-400 claps a
  second, -20 to -35 dBFS), **room** (hum, ventilation, pink noise, -45 to -60 dBFS) and
  white, pink and brown noise.

Clips are strung into programmes (music, then speech, then music, ...) so the statistics
cross every kind of boundary; features are computed on the whole programme (the beat
tracker too), and the statistics at both of the gate's time constants. ``dBFS`` here is
the RMS level of the signal, ``20 log10(rms)``.

Two networks are fitted on the same programmes: the detector (both time constants, all 12
statistics), which the idle performer judges by, and the **stop network** the dancing one
judges by (``presence_stop``: the dancing time constant only, the beat statistics
``BEAT_STATS`` left out; ``--no-stop-network``: none, as before it). ``--voice-network`` fits
only a third, the voice network of the voice-over rule (``presence_voice``: the stop network's
fit on programmes with half their music clips voiced, labelled music; the shipped one at seed 0).

Refit a checkpoint's detector (the rest of the checkpoint is copied unchanged); with
``--steadiness`` it also adds the spectral steadiness column (models/features/steadiness.py)
to the checkpoint's features, which the detector then reads in place of MFCC 1, at a
10-frame time constant and with music frames weighted 2 (:data:`STEADY_TAU`,
:data:`STEADY_MUSIC_WEIGHT`; the shipped default was made so)::

    .venv/bin/python -m models.training.music_gate --checkpoint models/assets/default.pt \\
        --data ../shared/data/dwm --out /tmp/default_gate.pt --steadiness

``performer train`` fits it too (:func:`models.training.dance_vq.set_statistics`). Exit
status 2 on a missing input, a checkpoint that is not dance_vq, or no espeak-ng.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch

from models.errors import DataError
from models.networks import music_gate as mg

SR: int = 22050
#: Words the synthetic speakers read, in random order with sentence breaks.
WORDS: tuple[str, ...] = tuple("""
the a and of to in is you that it he was for on are as with his they at be this have from or one had by word
but not what all were we when your can said there use an each which she do how their if will up other about
out many then them these so some her would make like him into time has look two more write go see number no
way could people my than first water been call who oil its now find long down day did get come made may part
thank you everyone good evening tonight welcome please next song band stage music dance let us hear it for
ladies gentlemen our friends thanks coming out really great show little break back minutes remember drinks
bar merchandise table after weather outside wonderful crowd city night again special guest give big hand
chapter story house morning mother father garden window letter journey river mountain village winter summer
""".split())
VOICES: tuple[str, ...] = ("en", "en-us", "en-gb-scotland", "en-gb-x-rp", "en-029", "en-us-nyc", "en-gb-x-gbclan",
                           "de", "fr", "es", "it", "nl", "pt")
VARIANTS: tuple[str, ...] = ("", "+m1", "+m2", "+m3", "+m4", "+m5", "+m6", "+m7", "+f1", "+f2", "+f3", "+f4", "+f5",
                             "+croak", "+klatt", "+klatt2", "+klatt3", "+whisper")


def _level(x: np.ndarray, dbfs: float) -> np.ndarray:
    """``x`` scaled to an RMS of ``dbfs`` dB full scale, clipped to [-1, 1], float32."""
    rms = float(np.sqrt(np.mean(np.square(x, dtype=np.float64)))) + 1e-12
    return np.clip(x * (10 ** (dbfs / 20) / rms), -1, 1).astype(np.float32)


def _env(n: int, decay_s: float, attack_s: float = 0.0) -> np.ndarray:
    t = np.arange(n) / SR
    e = np.exp(-t / max(decay_s, 1e-4))
    if attack_s > 0:
        e *= np.minimum(1.0, t / attack_s)
    return e


def _add(out: np.ndarray, x: np.ndarray, at: int) -> None:
    if at >= len(out):
        return
    m = min(len(x), len(out) - at)
    out[at: at + m] += x[:m]


def _lowpass(x: np.ndarray, hz: float) -> np.ndarray:
    from scipy.signal import butter, sosfilt

    return sosfilt(butter(2, min(hz, 0.45 * SR), fs=SR, output="sos"), x)


def _highpass(x: np.ndarray, hz: float) -> np.ndarray:
    from scipy.signal import butter, sosfilt

    return sosfilt(butter(2, hz, btype="high", fs=SR, output="sos"), x)


def colour(x: np.ndarray, rng: np.random.Generator, band_p: float) -> np.ndarray:
    """``x`` through a random microphone and channel: with probability ``band_p`` a steep low-pass
    (a 16-kHz or 22-kHz source's band edge, or anywhere in 5-10.5 kHz; one in six a telephone
    band), and half the time a tilt of the spectrum (more or less below 1 kHz)."""
    from scipy.signal import butter, sosfilt

    if rng.uniform() < band_p:
        if rng.uniform() < 1 / 6:
            x = sosfilt(butter(4, [300, 3400], btype="band", fs=SR, output="sos"), x)
        else:
            edge = float(rng.choice([7600.0, 10500.0, rng.uniform(5000, 10500)]))
            x = sosfilt(butter(8, edge, fs=SR, output="sos"), x)
    if rng.uniform() < 0.5:
        x = x + rng.uniform(-0.6, 1.0) * _lowpass(x, 1000)
    return x


def _osc(freq: np.ndarray, shape: str, rng: np.random.Generator) -> np.ndarray:
    """An oscillator (n,) following the per-sample frequency ``freq`` (Hz): saw, square, sine or tri."""
    ph = (np.cumsum(freq) / SR + rng.uniform()) % 1.0
    if shape == "saw":
        return 2 * ph - 1
    if shape == "square":
        return np.where(ph < 0.5, 1.0, -1.0)
    if shape == "tri":
        return 4 * np.abs(ph - 0.5) - 1
    return np.sin(2 * np.pi * ph)


def _midi(m: np.ndarray | float) -> np.ndarray:
    return 440.0 * 2 ** ((np.asarray(m, np.float64) - 69) / 12)


def _drum(kind: str, rng: np.random.Generator) -> np.ndarray:
    if kind == "kick":
        n = int(0.35 * SR)
        t = np.arange(n) / SR
        f = rng.uniform(40, 60) + rng.uniform(80, 200) * np.exp(-t / rng.uniform(0.015, 0.05))
        return np.sin(2 * np.pi * np.cumsum(f) / SR) * _env(n, rng.uniform(0.12, 0.35))
    if kind in ("snare", "clap"):
        n = int(0.3 * SR)
        noise = _highpass(rng.standard_normal(n), rng.uniform(800, 2000)) * _env(n, rng.uniform(0.04, 0.12))
        if kind == "clap":
            for d in (0.0, 0.011, 0.022):
                noise[int(d * SR):] += 0.6 * rng.standard_normal(n - int(d * SR)) * _env(n - int(d * SR), 0.008)
            return noise
        return noise + 0.6 * np.sin(2 * np.pi * rng.uniform(160, 240) * np.arange(n) / SR) * _env(n, 0.05)
    n = int(0.2 * SR)  # hat
    return 0.5 * _highpass(rng.standard_normal(n), rng.uniform(6000, 9000)) * _env(n, rng.uniform(0.015, 0.09))


def _drums(n: int, beat: float, pattern: str, rng: np.random.Generator) -> np.ndarray:
    """A drum-machine track (n,) with beats of ``beat`` s: "four", "break", "half" or "rock"."""
    out = np.zeros(n)
    kick, snare, hat = _drum("kick", rng), _drum("clap" if rng.uniform() < 0.4 else "snare", rng), _drum("hat", rng)
    steps = {"four": ([0, 4, 8, 12], [4, 12], [2, 6, 10, 14]),
             "break": ([0, 10], [4, 12], list(range(0, 16, 2))),
             "half": ([0, 6], [8], list(range(0, 16, 2))),
             "rock": ([0, 8, 10], [4, 12], list(range(0, 16, 2)))}[pattern]
    sixteenth = beat / 4
    swing = rng.uniform(0, 0.02)
    hat_all = rng.uniform() < 0.3
    for bar in range(int(n / SR / (4 * beat)) + 1):
        t0 = bar * 4 * beat
        for s in steps[0]:
            _add(out, kick * rng.uniform(0.85, 1.0), int((t0 + s * sixteenth) * SR))
        for s in steps[1]:
            _add(out, 0.7 * snare * rng.uniform(0.8, 1.0), int((t0 + s * sixteenth) * SR))
        for s in (range(16) if hat_all else steps[2]):
            _add(out, 0.4 * hat * rng.uniform(0.5, 1.0), int((t0 + s * sixteenth + (swing if s % 2 else 0)) * SR))
    return out


def electronic(seconds: float, rng: np.random.Generator) -> np.ndarray:
    """Synthetic electronic music (n,) float32 at 22050 Hz, -30 to -8 dBFS (module docstring)."""
    n = int(seconds * SR)
    bpm = rng.uniform(120, 190)
    beat = 60 / bpm
    t = np.arange(n) / SR
    bar = 4 * beat
    root = rng.integers(33, 45)  # A1..G#2
    prog = rng.choice([0, 3, 5, 7, 8, 10, -2], size=4)
    idx = (t // (bar * rng.choice([1, 2]))).astype(int) % 4
    note = root + prog[idx]
    mix = np.zeros(n)
    drums = rng.uniform() < 0.85
    if drums:
        mix += rng.uniform(0.6, 1.2) * _drums(n, beat, str(rng.choice(["four", "four", "break", "half"])), rng)
    pump = 1 - rng.uniform(0.3, 0.8) * np.exp(-(t % beat) / rng.uniform(0.05, 0.15)) if drums else np.ones(n)
    if rng.uniform() < 0.9:  # bass
        gate = ((t % (beat / 2)) >= beat / 4) if rng.uniform() < 0.5 else ((t % (beat / 4)) < beat / 8)
        b = _osc(_midi(note), str(rng.choice(["saw", "square", "sine"])), rng)
        mix += rng.uniform(0.3, 0.7) * _lowpass(b * gate, rng.uniform(300, 1500))
    sparse = drums and rng.uniform() < 0.4  # drums and bass only: gaps between the hits
    if not sparse and rng.uniform() < 0.8:  # pad: a chord of detuned saws, pumped
        pad = np.zeros(n)
        for iv in (12, 15 + rng.integers(0, 2), 19):
            for det in (-0.1, 0.0, 0.1):
                pad += _osc(_midi(note + iv + det), "saw", rng)
        mix += rng.uniform(0.05, 0.15) * _lowpass(pad, rng.uniform(1500, 6000)) * pump
    if not sparse and rng.uniform() < 0.6:  # arpeggio / lead
        steps = (t // (beat / rng.choice([2, 4]))).astype(int)
        arp = note + 24 + np.array([0, 3, 7, 12, 7, 3])[steps % 6]
        lead = _osc(_midi(arp), str(rng.choice(["saw", "square"])), rng) * np.exp(-((t % (beat / 4)) / 0.08))
        mix += rng.uniform(0.05, 0.2) * _lowpass(lead, rng.uniform(2000, 8000))
    if rng.uniform() < 0.3:  # a riser of filtered noise
        mix += rng.uniform(0.02, 0.1) * _lowpass(rng.standard_normal(n), 2000) * (t / max(seconds, 1e-3))
    mix = np.tanh(rng.uniform(0.5, 2.0) * mix / (np.abs(mix).max() + 1e-9))
    mix = reverb(mix, rng.uniform(0.3, 2.0), rng.uniform(0.05, 0.4), rng)  # a mix is rarely dry
    return _level(colour(mix, rng, 0.3), rng.uniform(-30, -8))


def tonal(seconds: float, rng: np.random.Generator) -> np.ndarray:
    """Synthetic acoustic-like music (n,) float32: piano / pluck notes, string pads, maybe rock drums."""
    n = int(seconds * SR)
    bpm = rng.uniform(60, 160)
    beat = 60 / bpm
    t = np.arange(n) / SR
    scale = np.array([0, 2, 4, 5, 7, 9, 11]) if rng.uniform() < 0.6 else np.array([0, 2, 3, 5, 7, 8, 10])
    key = rng.integers(48, 60)
    mix = np.zeros(n)
    voice = str(rng.choice(["piano", "pluck", "strings", "organ"]))
    step = beat / rng.choice([1, 2, 3, 4])
    deg = 0
    for k in range(int(seconds / step) + 1):
        deg = int(np.clip(deg + rng.integers(-2, 3), -7, 14))
        m = key + 12 * (deg // 7) + scale[deg % 7]
        dur = step * rng.choice([1, 1, 2])
        ln = int(min(dur + (1.0 if voice == "piano" else 0.3), 3.0) * SR)
        tt = np.arange(ln) / SR
        f0 = float(_midi(m))
        if voice == "strings":
            f = f0 * (1 + 0.004 * np.sin(2 * np.pi * 5.5 * tt))
            note = _lowpass(_osc(f, "saw", rng), 3000) * np.minimum(1, tt / 0.15) * np.exp(-np.maximum(0, tt - dur) / 0.2)
        else:
            note = np.zeros(ln)
            for h in range(1, 9):
                fh = f0 * h * (1 + 0.0004 * h * h if voice == "piano" else 1)
                if fh > 0.45 * SR:
                    break
                decay = (1.2 if voice == "piano" else 0.3 if voice == "pluck" else 5.0) / h ** 0.5
                note += np.sin(2 * np.pi * fh * tt) / h * np.exp(-tt / decay)
            if voice == "organ":
                note *= np.exp(-np.maximum(0, tt - dur) / 0.05)
        _add(mix, rng.uniform(0.5, 1.0) * note, int(k * step * SR))
        if k % 4 == 0 and rng.uniform() < 0.7:  # a chord under it
            for iv in (0, scale[2], 7):
                _add(mix, 0.4 * np.sin(2 * np.pi * float(_midi(key - 12 + iv)) * tt) * np.exp(-tt / 1.5), int(k * step * SR))
    if rng.uniform() < 0.35:  # a rock band: drums and distorted chords
        mix = mix / (np.abs(mix).max() + 1e-9) + rng.uniform(0.4, 1.0) * _drums(n, beat, "rock", rng)
        gtr = sum(_osc(_midi(key - 12 + iv + 0 * t), "saw", rng) for iv in (0, 7, 12))
        mix += rng.uniform(0.1, 0.4) * _lowpass(np.tanh(4 * gtr), 3000)
    mix = mix / (np.abs(mix).max() + 1e-9)
    mix = reverb(mix, rng.uniform(0.3, 2.5), rng.uniform(0.1, 0.5), rng)
    return _level(colour(mix, rng, 0.3), rng.uniform(-35, -10))


def reverb(x: np.ndarray, rt_s: float, wet: float, rng: np.random.Generator) -> np.ndarray:
    """``x`` with a synthetic room (exponentially decaying noise impulse response, RT60 ``rt_s``)."""
    from scipy.signal import fftconvolve

    n = int(rt_s * SR)
    ir = rng.standard_normal(n) * np.exp(-6.9 * np.arange(n) / max(n, 1))
    ir /= np.sqrt(np.sum(ir ** 2)) + 1e-9
    return (1 - wet) * x + wet * fftconvolve(x, ir)[: len(x)]


#: With the steadiness column (``--steadiness``): the statistics' time constant while dancing
#: (frames; the model's ``gate_tau``) and the weight of music frames in the fit. Measured on
#: the judging set (docs/listening.md, "Knowing when music plays"): at 15 frames and equal
#: weights a reader between songs took 2.8 s to idle and a rumba (DANCE_R_5) idled 5 % of
#: the time; at 10 frames with music weighted 2, 2.4 s and 0.5 %. Faster still (8 frames)
#: the reader was no longer held idle.
STEADY_TAU: float = 10.0
STEADY_MUSIC_WEIGHT: float = 2.0
#: Share of the programmes' music clips with a voice over them (:func:`voiced`), labelled
#: music to the stop network (``--voice-over``): a rapper, a DJ or a host over a track is music,
#: only a voice alone is not. 0 (the shipped networks): none. The shipped stop network idles 1-29 %
#: of the shared recordings with speech over them at 0 dB; refitted with 0.5 (--stop-only), 0-13 %,
#: but one fit idled a drums-and-bass recording alone 15 % of its length: not shipped
#: (docs/history-listening.md, "Listening, second round").
VOICE_OVER: float = 0.0
#: Share of voiced music clips in the voice network's programmes (``--voice-network``, the
#: voice-over rule of models/networks/music_gate.py; the shipped one: 0.5, seed 0).
VOICE_NETWORK_SHARE: float = 0.5
#: The label of those clips' frames: music to the stop network; the detector that starts an idle
#: performer leaves them out (fitted on them, it started on a host's voice alone: a reading
#: between two songs held the idle 74 % of its length instead of 100 %).
VOICED: int = 2
#: Level of that voice, dB relative to the music's RMS level (uniform in this range).
VOICE_OVER_DB: tuple[float, float] = (-12.0, 6.0)


def espeak_available() -> bool:
    return shutil.which("espeak-ng") is not None


def say(text: str, voice: str, rate: int, pitch: int) -> np.ndarray:
    """espeak-ng speaking ``text`` (n,) float32 at 22050 Hz; DataError without espeak-ng."""
    import soundfile as sf

    if not espeak_available():
        raise DataError("espeak-ng is not installed (apt-get install -y espeak-ng; the Makefile's APT_PKGS has it)")
    with tempfile.TemporaryDirectory() as d:
        wav = Path(d) / "s.wav"
        subprocess.run(["espeak-ng", "-v", voice, "-s", str(rate), "-p", str(pitch), "-w", str(wav), text],
                       check=True, capture_output=True)
        x, sr = sf.read(wav, dtype="float32")
    if sr != SR:
        from models.features.resample import resample

        x = resample(x, sr, SR)
    return np.asarray(x, np.float32)


def _sentence(rng: np.random.Generator) -> str:
    words = rng.choice(WORDS, size=int(rng.integers(4, 16)))
    return " ".join(words).capitalize() + str(rng.choice([".", ".", ",", "?", "!"]))


def utterance(rng: np.random.Generator) -> np.ndarray:
    """A few sentences by one random voice (n,), dry, peak 1."""
    voice = str(rng.choice(VOICES)) + str(rng.choice(VARIANTS))
    x = say(" ".join(_sentence(rng) for _ in range(int(rng.integers(2, 5)))), voice,
            int(rng.integers(110, 230)), int(rng.integers(20, 80)))
    return x / (np.abs(x).max() + 1e-9)


def speech(seconds: float, rng: np.random.Generator, pool: list[np.ndarray] | None = None) -> np.ndarray:
    """Someone talking (n,) float32: utterances with 0.1-1.2 s pauses, a room, a noise bed, -35 to -10 dBFS."""
    n = int(seconds * SR)
    out = np.zeros(n)
    at = int(rng.uniform(0, 0.3) * SR)
    while at < n:
        u = pool[int(rng.integers(len(pool)))] if pool else utterance(rng)
        _add(out, u * rng.uniform(0.6, 1.0), at)
        at += len(u) + int(rng.uniform(0.1, 1.2) * SR)
    out = reverb(out, rng.uniform(0.1, 0.8), rng.uniform(0.0, 0.5), rng)
    if rng.uniform() < 0.5:
        out = _highpass(out, rng.uniform(80, 200))
    out = _level(colour(out, rng, 0.6), -20) + _level(_noise("pink", n, rng), -20 - rng.uniform(15, 45))
    return _level(out, rng.uniform(-35, -10))


def _noise(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    from scipy.signal import lfilter

    w = rng.standard_normal(n)
    if kind == "pink":
        return lfilter([0.049922035, -0.095993537, 0.050612699, -0.004408786], [1, -2.494956002, 2.017265875, -0.522189400], w)
    if kind == "brown":
        return lfilter([1.0], [1, -0.995], w)
    return w


def babble(seconds: float, rng: np.random.Generator, pool: list[np.ndarray], dbfs: float | None = None) -> np.ndarray:
    """A crowd talking (n,) float32: 6-30 voices from ``pool``, a room, at ``dbfs`` (default: -45 to -30 dBFS)."""
    n = int(seconds * SR)
    out = np.zeros(n)
    for _ in range(int(rng.integers(6, 31))):
        at = -int(rng.uniform(0, 3) * SR)
        g = rng.uniform(0.2, 1.0)
        while at < n:
            u = pool[int(rng.integers(len(pool)))]
            lo = max(0, -at)
            _add(out, g * u[lo:], max(at, 0))
            at += len(u) + int(rng.uniform(0.1, 1.0) * SR)
    out = colour(reverb(out, rng.uniform(0.4, 1.5), rng.uniform(0.3, 0.7), rng), rng, 0.3)
    return _level(out, rng.uniform(-45, -30) if dbfs is None else dbfs)


def applause(seconds: float, rng: np.random.Generator, pool: list[np.ndarray] | None = None,
             dbfs: float | None = None) -> np.ndarray:
    """Applause (n,) float32: 20-400 claps a second (one clapper to a hall), maybe cheering, at
    ``dbfs`` (default: -35 to -20 dBFS)."""
    n = int(seconds * SR)
    out = np.zeros(n)
    rate = float(np.exp(rng.uniform(np.log(20), np.log(400))))
    fade = np.minimum(1, np.minimum(np.arange(n) / (SR * rng.uniform(0.05, 1.0)), (n - np.arange(n)) / (SR * rng.uniform(0.5, 3))))
    ln = int(0.03 * SR)
    tt = np.arange(ln) / SR
    for at in rng.uniform(0, seconds, int(rate * seconds)):
        c = rng.standard_normal(ln) * np.exp(-tt / rng.uniform(0.003, 0.012))
        i = int(at * SR)
        if i + ln < n:
            out[i: i + ln] += rng.uniform(0.3, 1.0) * c
    out = _highpass(out, rng.uniform(300, 800))
    if pool and rng.uniform() < 0.4:
        out = out / (np.abs(out).max() + 1e-9) + rng.uniform(0.05, 0.3) * babble(seconds, rng, pool)
    out = reverb(out * fade, rng.uniform(0.5, 2.0), rng.uniform(0.2, 0.6), rng)
    return _level(out, rng.uniform(-35, -20) if dbfs is None else dbfs)


def room(seconds: float, rng: np.random.Generator, pool: list[np.ndarray] | None = None,
         dbfs: float | None = None) -> np.ndarray:
    """Room tone (n,) float32: ventilation, mains hum, pink noise, maybe distant talk, at ``dbfs``
    (default: -60 to -45 dBFS)."""
    n = int(seconds * SR)
    t = np.arange(n) / SR
    mains = rng.choice([50.0, 60.0])
    out = _lowpass(_noise("white", n, rng), rng.uniform(200, 2000)) + rng.uniform(0.2, 1) * _noise("pink", n, rng) / 10
    out = out / (np.abs(out).max() + 1e-9)
    out += rng.uniform(0, 0.3) * sum(np.sin(2 * np.pi * mains * h * t) / h for h in (1, 2, 3))
    if pool and rng.uniform() < 0.4:
        out += rng.uniform(0.1, 0.5) * babble(seconds, rng, pool) / 10 ** (-37.5 / 20)
    return _level(out, rng.uniform(-60, -45) if dbfs is None else dbfs)


def plain_noise(seconds: float, rng: np.random.Generator, kind: str | None = None, dbfs: float | None = None) -> np.ndarray:
    """White, pink or brown noise (n,) float32 (``kind``; default one at random), at ``dbfs`` (default -50 to -15 dBFS)."""
    kind = str(rng.choice(["white", "pink", "brown"])) if kind is None else kind
    return _level(_noise(kind, int(seconds * SR), rng), rng.uniform(-50, -15) if dbfs is None else dbfs)


def voiced(music: np.ndarray, rng: np.random.Generator, pool: list[np.ndarray]) -> np.ndarray:
    """``music`` (n,) with someone talking over it (:func:`speech`) at :data:`VOICE_OVER_DB` dB
    relative to the music's RMS level (a rapper, a DJ or a host over the track): still music."""
    talk = speech(len(music) / SR + 0.1, rng, pool)[: len(music)]
    rel = 10 ** (rng.uniform(*VOICE_OVER_DB) / 20)
    gain = rel * (np.sqrt(np.mean(np.square(music, dtype=np.float64))) + 1e-12) / (
        np.sqrt(np.mean(np.square(talk, dtype=np.float64))) + 1e-12)
    return np.clip(music + gain * talk, -1, 1).astype(np.float32)


def programme(rng: np.random.Generator, songs: list[np.ndarray], pool: list[np.ndarray],
              seconds: float = 120.0, voice_over: float = VOICE_OVER) -> tuple[np.ndarray, np.ndarray]:
    """A random programme (audio (n,), music label per 30-fps frame (n // 735,) int8: 1 music, 0 not,
    :data:`VOICED` music with a voice over it): clips of 4-20 s, music and not music alternating
    at random; a ``voice_over`` share of the music clips has a voice over it (:func:`voiced`)."""
    from models.timebase import HOP

    parts, labels = [], []
    total = 0
    while total < seconds * SR:
        music = rng.uniform() < 0.5
        s = rng.uniform(4, 20)
        if music:
            kind = rng.choice(["song", "electronic", "electronic", "tonal"]) if songs else rng.choice(["electronic", "tonal"])
            if kind == "song":
                song = songs[int(rng.integers(len(songs)))]
                a = int(rng.integers(0, max(1, len(song) - int(s * SR))))
                x = _level(colour(song[a: a + int(s * SR)], rng, 0.3), rng.uniform(-35, -10))
            else:
                x = electronic(s, rng) if kind == "electronic" else tonal(s, rng)
            if voice_over > 0.0 and rng.uniform() < voice_over:
                x, music = voiced(x, rng, pool), VOICED
        else:
            kind = rng.choice(["speech", "speech", "speech", "babble", "applause", "room", "noise"])
            x = {"speech": lambda: speech(s, rng, pool), "babble": lambda: babble(s, rng, pool),
                 "applause": lambda: applause(s, rng, pool), "room": lambda: room(s, rng, pool),
                 "noise": lambda: plain_noise(s, rng)}[str(kind)]()
        x = x[: (len(x) // HOP) * HOP]
        parts.append(x)
        labels.append(np.full(len(x) // HOP, int(music), np.int8))
        total += len(x)
    return np.concatenate(parts).astype(np.float32), np.concatenate(labels)


def programme_features(fcfg, songs: list[np.ndarray], rng: np.random.Generator, minutes: float = 60.0,
                       pool_size: int = 80, progress: bool = False,
                       voice_over: float = VOICE_OVER) -> list[tuple[np.ndarray, np.ndarray]]:
    """``minutes`` of random :func:`programme` s (``voice_over``: theirs) as (features (T, D), labels (T,)) pairs."""
    from models.features.spectral import extract_features

    pool = [utterance(rng) for _ in range(pool_size)]
    if progress:
        print(f"music gate: {len(pool)} espeak-ng utterances", flush=True)
    out = []
    for i in range(int(math.ceil(minutes / 2))):
        audio, lab = programme(rng, songs, pool, 120.0, voice_over)
        out.append((extract_features(audio, fcfg), lab))
        if progress:
            print(f"music gate: programme {i + 1}: {len(lab) / 30:.0f} s, {lab.mean():.2f} music", flush=True)
    return out


def training_rows(model, progs: list[tuple[np.ndarray, np.ndarray]],
                  taus: tuple[float, ...] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Statistics (N, N_STATS) and labels (N,) of programmes (:func:`programme_features`), at each
    time constant of ``taus`` (frames; default both of the gate's, the model's ``gate_tau`` and
    ``TAU_IDLE``); the first 3 s, frames up to 4 after a change of label and silence (log energy
    at most the model's threshold) left out."""
    fm, fs = model.feat_mean.numpy(), model.feat_std.numpy()
    energy_min = float(model.gate[0])
    xs, ys = [], []
    for feats, lab in progs:
        keep = np.ones(len(lab), bool)
        for c in np.flatnonzero(np.diff(lab)) + 1:
            keep[c: c + 5] = False
        keep &= feats[:, mg.ENERGY_COL] > energy_min
        keep[:90] = False  # the start of a stream: the beat tracker's window is empty
        for tau in taus or (model.config.gate_tau, mg.TAU_IDLE):
            xs.append(mg.stats_trace(feats, fm, fs, model.config.clarity_col, tau, model.config.gate_col)[keep])
            ys.append(lab[keep])
    return np.concatenate(xs), np.concatenate(ys).astype(np.float32)


def fit_network(x: np.ndarray, y: np.ndarray, seed: int = 0, steps: int = 400, music_weight: float = 1.0,
                drop: tuple[int, ...] = ()) -> np.ndarray:
    """The detector's packed parameters (:func:`models.networks.music_gate.pack`) fitted on
    statistics ``x`` (N, N_STATS; a study may pass others, N, S) and labels ``y`` (N,) by weighted cross-entropy (classes equal,
    then music frames ``music_weight`` times the others), L-BFGS for ``steps`` iterations. The
    statistics in ``drop`` are left out: they read 0 in the fit and get no weight (mean 0, std 1,
    zero columns of W1), whatever their values at run time."""
    torch.manual_seed(seed)
    mean, std = x.mean(0), np.maximum(x.std(0), 1e-3)
    cols = list(drop)
    mean[cols], std[cols] = 0.0, 1.0
    z = (x - mean) / std
    z[:, cols] = 0.0
    xt = torch.from_numpy(z.astype(np.float32))
    yt = torch.from_numpy(y)
    pos = float(y.mean())
    wt = torch.where(yt > 0.5, 0.5 / max(pos, 1e-6), 0.5 / max(1 - pos, 1e-6))
    if music_weight != 1.0:
        wt = torch.where(yt > 0.5, music_weight * wt, wt)
        wt = wt / wt.mean()
    net = torch.nn.Sequential(torch.nn.Linear(x.shape[1], mg.HIDDEN), torch.nn.Tanh(), torch.nn.Linear(mg.HIDDEN, 1))
    opt = torch.optim.LBFGS(net.parameters(), max_iter=steps, line_search_fn="strong_wolfe")

    def closure() -> torch.Tensor:
        opt.zero_grad()
        loss = (wt * torch.nn.functional.binary_cross_entropy_with_logits(net(xt)[:, 0], yt, reduction="none")).mean()
        loss = loss + 1e-4 * sum(p.pow(2).sum() for p in net.parameters())
        loss.backward()
        return loss

    opt.step(closure)
    w1, b1 = net[0].weight.detach().numpy().copy(), net[0].bias.detach().numpy()
    w1[:, cols] = 0.0
    w2, b2 = net[2].weight.detach().numpy()[0], float(net[2].bias.detach()[0])
    return mg.pack(mean, std, w1, b1, w2, b2)


def fit_presence(model, fcfg, songs: list[np.ndarray], rng: np.random.Generator, minutes: float = 60.0,
                 progress: bool = False, music_weight: float = 1.0, stop: bool = True,
                 stop_only: bool = False, voice_over: float = VOICE_OVER, voice_network: bool = False) -> dict[str, float]:
    """Fit ``model``'s presence detector (its ``presence`` buffer) on ``songs`` (training songs'
    audio, (n,) at 22050 Hz) and the synthetic material (:func:`fit_network`'s ``music_weight``),
    and with ``stop`` its stop network (``presence_stop``: the same programmes' statistics at
    the dancing time constant only, the beat statistics ``BEAT_STATS`` left out; else zeros);
    returns the training accuracy per class (``stop_`` keys: the stop network's). ``stop_only``:
    the model's detector is kept as it is and only the stop network is fitted; ``voice_over``:
    :func:`programme`'s. ``voice_network``: only the voice network (``presence_voice``, the
    voice-over rule of models/networks/music_gate.py) is fitted, as the stop network is but on
    programmes with ``voice_over`` (:data:`VOICE_NETWORK_SHARE` when 0) of their music voiced;
    the detector and the stop network are kept."""
    if voice_network:
        progs = programme_features(fcfg, songs, rng, minutes, progress=progress,
                                   voice_over=voice_over or VOICE_NETWORK_SHARE)
        xs, ys = training_rows(model, progs, taus=(model.config.gate_tau,))
        ys = np.minimum(ys, 1.0)  # a voice over music is music
        rng.integers(1 << 30)  # the detector's seed, unused: the same draws as --voice-over --stop-only
        pv = fit_network(xs, ys, int(rng.integers(1 << 30)), music_weight=music_weight, drop=mg.BEAT_STATS)
        with torch.no_grad():
            model.presence_voice.copy_(torch.from_numpy(pv))
        acc = {f"voice_{k}": v for k, v in _accuracy(pv, xs, ys).items()}
        if progress:
            print(f"music gate: voice network {acc['voice_music_acc']:.3f} of music frames (voiced too), "
                  f"{acc['voice_other_acc']:.3f} of other frames right ({len(ys)} rows)")
        return acc
    progs = programme_features(fcfg, songs, rng, minutes, progress=progress, voice_over=voice_over)
    x, y = training_rows(model, progs)
    x, y = x[y != VOICED], y[y != VOICED]  # the idle performer's detector: a voice over music left out
    seed = int(rng.integers(1 << 30))
    p = model.presence.numpy().copy() if stop_only else fit_network(x, y, seed, music_weight=music_weight)
    acc = {**_accuracy(p, x, y), "frames": float(len(y))}
    ps = np.zeros_like(p)
    if stop:
        xs, ys = training_rows(model, progs, taus=(model.config.gate_tau,))
        ys = np.minimum(ys, 1.0)  # a voice over music is music
        ps = fit_network(xs, ys, int(rng.integers(1 << 30)), music_weight=music_weight, drop=mg.BEAT_STATS)
        acc.update({f"stop_{k}": v for k, v in _accuracy(ps, xs, ys).items()})
    with torch.no_grad():
        model.presence.copy_(torch.from_numpy(p))
        model.presence_stop.copy_(torch.from_numpy(ps))
    if progress:
        print(f"music gate: {acc['music_acc']:.3f} of music frames, {acc['other_acc']:.3f} of other frames right "
              f"({len(y)} rows)" + (f"; stop network (dancing, no beat statistics): {acc['stop_music_acc']:.3f}, "
                                    f"{acc['stop_other_acc']:.3f}" if stop else ""))
    return acc


def _accuracy(p: np.ndarray, x: np.ndarray, y: np.ndarray) -> dict[str, float]:
    """Share of music rows (``y`` 1) with a positive logit and of the others with a non-positive one."""
    mean, std, w1, b1, w2, b2 = mg.unpack(p)
    logit = np.tanh(((x - mean) / np.maximum(std, 1e-6)) @ w1.T + b1) @ w2 + b2[0]
    return {"music_acc": float((logit[y > 0.5] > 0).mean()), "other_acc": float((logit[y < 0.5] <= 0).mean())}


def training_songs(data_root: str | Path) -> list[str]:
    """The training split's dance names (models.data.split), in its order: the songs the detector hears."""
    from models.data.dwm import dance_dirs
    from models.data.split import split_names

    return split_names([d.name for d in dance_dirs(data_root)])[0]


def song_audio(data_root: str | Path, names: list[str]) -> list[np.ndarray]:
    """The training songs' audio (n,) at 22050 Hz."""
    from models.data.dwm import load_dance
    from models.features.audio_io import load_audio

    return [load_audio(load_dance(Path(data_root) / n).audio_path, SR)[0] for n in names]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] + " See the module docstring.")
    p.add_argument("--checkpoint", required=True, metavar="CKPT", help="a dance_vq checkpoint")
    p.add_argument("--data", required=True, metavar="DIR", help="the DWM dataset directory (its training songs)")
    p.add_argument("--out", required=True, metavar="CKPT", help="where to write the checkpoint with the fitted detector")
    p.add_argument("--minutes", type=float, default=60.0, help="minutes of training programmes (default 60)")
    p.add_argument("--seed", type=int, default=0, help="seed of the synthetic material and the fit (default 0)")
    p.add_argument("--no-stop-network", action="store_true",
                   help="fit only the one network for both states, as checkpoints before the stop network "
                        "(default: also the stop network the dancing performer judges by)")
    p.add_argument("--voice-over", type=float, default=VOICE_OVER, metavar="SHARE",
                   help="share of the music clips with a voice over them, music to the stop network "
                        f"(default {VOICE_OVER:g}: none)")
    p.add_argument("--stop-only", action="store_true",
                   help="keep the checkpoint's detector (the idle performer's) and refit only the stop network")
    p.add_argument("--voice-network", action="store_true",
                   help="fit only the voice network of the voice-over rule (presence_voice: a voice over the music "
                        f"is music) on programmes with --voice-over (default {VOICE_NETWORK_SHARE:g}) of the music "
                        "voiced; the detector and the stop network are kept")
    p.add_argument("--steadiness", action="store_true",
                   help="add the spectral steadiness column to the checkpoint's features (models/features/steadiness.py): "
                        "the detector reads it instead of MFCC 1, the predictor never does")
    a = p.parse_args(argv)

    from models.errors import PerformerError
    from models.generate import load_model
    from models.networks.checkpoint import save_checkpoint
    from models.networks.dance_vq import DanceVQ

    torch.set_num_threads(1)
    try:
        lm = load_model(a.checkpoint)
        if not isinstance(lm.model, DanceVQ):
            raise PerformerError(f"{lm.path} is a {lm.name!r} model; the presence detector is dance_vq's")
        fcfg, meta = lm.features, lm.meta
        feature_config = meta["feature_config"]
        if a.steadiness and not fcfg.steadiness:
            fcfg = dataclasses.replace(fcfg, steadiness=True)
            lm.model.config = dataclasses.replace(lm.model.config, gate_col=lm.model.config.feature_dim,
                                                  gate_tau=STEADY_TAU)
            feature_config = fcfg.to_dict()
        songs = song_audio(a.data, training_songs(a.data))
        fit_presence(lm.model, fcfg, songs, np.random.default_rng(a.seed), a.minutes, progress=True,
                     stop=not a.no_stop_network, stop_only=a.stop_only, voice_over=a.voice_over,
                     voice_network=a.voice_network,
                     music_weight=STEADY_MUSIC_WEIGHT if fcfg.steadiness else 1.0)
        save_checkpoint(a.out, lm.model, model_name=meta["model_name"], generator_config=lm.model.config,
                        feature_config=feature_config, rig=meta["rig"], extra=meta.get("extra"))
    except (PerformerError, OSError, subprocess.CalledProcessError) as e:
        print(f"music_gate: {e}", file=sys.stderr)
        return 2
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

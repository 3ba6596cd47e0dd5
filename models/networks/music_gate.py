"""Knowing when music plays: the presence detector of the dancing performer's idle gate.

:class:`MusicGate` reads one feature frame at a time (30 fps, the ``mfcc_onset`` kind with
context and beat columns: MFCC 0-12, log energy (dB) 13, their backward differences 14-27,
onset 28, context means 29-57, beat columns c cos, c sin, clarity, log2 period/15 58-61)
and keeps :data:`N_STATS` causal running statistics (one compiled call a frame,
:func:`presence_step`), all exponential means with time constant ``tau`` frames:

* 0: with the model's steadiness column (``gate_col``, models/features/steadiness.py), its
  running mean: how still the harmonics hold over 67 ms (music holds notes; a voice glides,
  noise has none). Without it (checkpoints fitted before it), the standardised MFCC 1, the
  spectrum's tilt, which follows the microphone and the room as much as the source: it took
  a close-miked reader for music;
* 1: the standardised MFCC 2 (the spectrum's curvature; the finer shape follows the recording
  chain more than the source, and is left out);
* 2: log of the mean squared standardised MFCC 1-12 difference (cepstral flux: speech
  and applause change shape fast, mixed music slowly);
* 3: the spread (dB) of the log energy around its running mean;
* 4: how often the energy lies 10 dB or more below its running mean (pauses);
* 5, 6: the mean and the log spread of the onset strength;
* 7: the beat tracker's pulse clarity (its own 6-s window);
* 8: the running mean of the log energy (dB) / 10 (level: room noise is quiet);
* 9: the mean absolute log-energy difference (dB a frame);
* 10: the beat phase's coherence (time constant :data:`TAU_BEAT`), the mean of ``cos(theta[t] - theta[t-1] - 2 pi / P[t])``
  (a steady pulse advances its phase by one period's share a frame);
* 11: the beat period's jitter, the log mean of ``|log2 P[t] - log2 P[t-1]|``.

A small network (:data:`N_STATS` -> :data:`HIDDEN` tanh -> 1) turns them into a logit
(music > 0), its weights and the statistics' standardisation in the model's ``presence``
buffer (:func:`pack` / :func:`unpack`; all zeros: not fitted, the stream keeps the older
logistic detector). A model may carry a second one for the dancing performer, the **stop
network** (``presence_stop``; all zeros: none, the one network in both states): it gives no
weight to the beat statistics 7, 10 and 11 (:data:`BEAT_STATS`), which remember the song
for seconds (the beat tracker's 6-s window, the 1.5-s coherence) and so held the logit up
for about 1.3 s after a host started talking; the idle performer keeps the network with
them, whose "no steady pulse" holds the idle through a reading. Both are fitted by
:mod:`models.training.music_gate` on the training songs and on synthetic electronic music,
espeak-ng speech, crowd babble, applause and room noise. While music is playing the
statistics run with the time constant the detector was fitted at (the model's ``gate_tau``:
:data:`TAU_MUSIC`, 15 frames, or 10 with the steadiness column) and the performer stops only
below ``-``:data:`MARGIN_STOP`; while it is not, with
:data:`TAU_IDLE` (so they forget the gap quickly) and it starts again above
:data:`MARGIN_START`. In silence (log energy at most the model's threshold) the
statistics are frozen and the gate says "no music".

**A voice over the music is music** (issue 43: a rapper, a DJ or a host over a track). Both
networks hear a voice as "no music", over a song too. A model may carry a third, the **voice
network** (``presence_voice``, the stop network's statistics, fitted with espeak-ng voices over
half the music clips labelled music; all zeros: none, no such rule). While the performer
dances, a frame the stop network hears as no music still counts as music when the voice
network hears music (logit above ``-``:data:`VOICE_MARGIN`) and the music keeps a floor under
the voice: the log energy's range over the last :data:`FLOOR_FRAMES` sounding frames is under
:data:`FLOOR_DB` (a voice alone falls 20-30 dB between its words, over music only to the
music's level; a crowd or noise has no pauses, but there the voice network hears no music).
``voice_rule=False`` switches it off.

**The voice-over start** (part of the voice-over rule): an idle performer's frame also counts as
music once both cues of the rule above have held for 1.5 s, and **the resume**: a performer that a
voice over the music stopped starts again from what it had heard (:mod:`models.networks.voice_start`,
composed here). ``start_rule=False`` (or ``voice_rule=False``) switches both off,
``resume_rule=False`` the resume alone (the count starts from 0 at the stop).

**The three networks agree** (issue 43, back within 1 s of the music): an idle performer that has
danced in this stream also hears music where the detector, the stop and the voice network all lean to
music (:mod:`models.networks.agreement`, composed here; ``agree_rule = False`` switches it off; a
checkpoint without both networks has none).

**The music's sharp return** (issue 43, back within 1 s): right after a silence, or on a frame far over the
gap's level, an idle performer that has danced takes the stop or the voice network's word alone
(:mod:`models.networks.sharp_return`, composed here; ``sharp_return.rule = False`` switches it off; ``sharp_return.rise``
is set by the idle gate).

**The voice network confirms a restart** (issue 43, held): soon after a stop, or later without a rise in
level, a start of the detector's alone, not right after a silence, waits until the voice network hears music too
(:mod:`models.networks.return_confirm`, composed here: :meth:`MusicGate.confirms_start`;
``return_confirm.rule = False`` switches it off).

**The veto** (issue 43: a crowd after a song): a dancing performer's frame the stop network is
unsure of is no music when the voice network is sure there is none and the floor holds
(:mod:`models.networks.veto`, composed here; ``MusicGate.veto.counting``, set by the idle gate, widens its
reach while a stop count runs). ``veto_rule=False`` switches it off.

**After a silence the statistics listen afresh** (issue 43, the slow settles). In silence they
wait, so after a song that ends in silence they still hold the song when a voice begins (a
reader's first 0.4 s of silence after a confident song: the stop network's logit +10 to +13,
0.9 s to fall under ``-``:data:`MARGIN_STOP`). The first :data:`FRESH_FRAMES` sounding frames
after :data:`FRESH_SILENCE` or more silent ones run at the idle time constant whatever the state.
``fresh_rule=False`` switches it off.

**The music heard in the voice's pauses** (the pause rule, part of the voice-over rule; with
the steadiness column only): a dancing performer's frame the stop network hears as no music also
counts as music when the steadiness in the quietest quarter of the last 0.67 s holds as music's
does (:mod:`models.networks.voice_pauses`, composed here). ``pause_rule=False`` (or
``voice_rule=False``) switches it off.

**The voice-over context** (part of the voice-over rule; issue 43, the voices at 0 dB): a dance in
which a voice has been heard over the music before holds its stop a while, unless the music is gone
(:mod:`models.networks.voice_context`, composed here: :meth:`MusicGate.voice_holds`).
``context_rule=False`` switches the context off. **A voice heard where the stop network wavers** (issue 43, a
voice that comes in after an instrumental start) is evidence for the context too (:mod:`models.networks.unsure_voice`,
composed here; ``unsure_rule = False`` switches it off).

**The lone voice** (part of the voice-over rule; issue 43, a host after a song): in a dance the
voice-over context has judged and heard no voice over, the pause rule does not keep a frame the voice
network is sure of, and one it leans to holds the stop count (:mod:`models.networks.lone_voice`,
composed here; ``lone.holding``, read by the idle gate). ``lone.rule = False`` switches it off.

**The song's end** (part of the voice-over rule; issue 43, a host after a song): in such a dance, after the
stop network fell from sure music to none within the statistics' time constant, the voice-over and pause
rules keep no frame the voice network does not lean to music on until the stop network hears music again
(:mod:`models.networks.song_end`, composed here; ``song_end.rule = False`` switches it off).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from models.networks.agreement import Agreement
from models.networks.false_start import FalseStart
from models.networks.lone_voice import LoneVoice
from models.networks.return_confirm import ReturnConfirm
from models.networks.sharp_return import SharpReturn
from models.networks.song_end import SongEnd
from models.networks.unsure_voice import UnsureVoice
from models.networks.veto import Veto
from models.networks.voice_context import VoiceContext
from models.networks.voice_pauses import VoicePauses, pause_steadiness
from models.networks.voice_start import VoiceStart

#: Statistics the detector reads (see the module docstring).
N_STATS: int = 12
#: Hidden units of the detector's network.
HIDDEN: int = 16
#: Time constant (frames) of the statistics while the performer dances (0.5 s), the default:
#: a model's detector runs at the one it was fitted at (``DanceVQConfig.gate_tau``; the
#: shipped one, with the steadiness column, at 10).
TAU_MUSIC: float = 15.0
#: Time constant (frames) while it is idle (0.2 s): the dance comes back within a second.
TAU_IDLE: float = 6.0
#: Time constant (frames) of the beat phase's coherence and the period's jitter, whatever
#: the state (1.5 s: the beat tracker itself reads 6 s).
TAU_BEAT: float = 45.0
BEAT_A: float = math.exp(-1.0 / TAU_BEAT)
#: Time constant (frames) of the running mean of the detector's logit that the margins judge
#: while the performer dances (while it is idle the logit itself).
LOGIT_TAU: float = 4.0
#: Logit below which a dancing performer hears no music.
MARGIN_STOP: float = 2.0
#: A dancing performer's frame whose logit (the running mean) lies ``k`` times
#: :data:`MARGIN_STOP` below 0 counts ``k`` frames, from 1 up to this many, towards the stop
#: (``idle_gate.ABSENT_FRAMES``, :meth:`MusicGate.stop_count`): a detector that is sure
#: stops in 8 frames, one near its margin still waits 15 (loud applause right after a song:
#: fully idle at 1.93 s instead of 2.10; the song's own dips below the margin stay shallow).
SURE_COUNT: float = 2.0
#: Statistics the stop network gives no weight (the pulse clarity, the beat phase's coherence,
#: the period's jitter: module docstring).
BEAT_STATS: tuple[int, ...] = (7, 10, 11)
#: Logit above which an idle performer hears music again.
MARGIN_START: float = 1.5
#: Frames of music an idle performer must hear before it dances again (0.1 s; the fade
#: after it takes 0.53 s: back within a second).
START_FRAMES: int = 3
#: The voice-over rule (module docstring): the voice network's logit above minus this hears
#: music, while the log energy's range (dB) over the last FLOOR_FRAMES sounding frames (1 s) lies
#: under FLOOR_DB. Chosen on espeak-ng voices over training songs and synthetic music; FLOOR_DB
#: 18, not 21, after a shared reader took 3.07 s to idle at 21 (docs/history-listening.md, issue 43).
VOICE_MARGIN: float = 1.0
FLOOR_FRAMES: int = 30
FLOOR_DB: float = 18.0
#: After a silence (module docstring): FRESH_FRAMES sounding frames (0.5 s, as ABSENT_FRAMES) after
#: FRESH_SILENCE silent ones or more (0.2 s, as TAU_IDLE) run at the idle time constant. Not tuned on
#: the readers: 30 frames took trance with 1-s breaks to 2.1 % idle (docs/presence.md).
FRESH_SILENCE: int = 6
FRESH_FRAMES: int = 15
#: Feature columns read: MFCC 1-2, log energy, MFCC 1-12 differences, energy difference, onset
#: (and the beat columns: the model's ``clarity_col`` and its neighbours).
MFCC_COLS: tuple[int, ...] = (1, 2)
ENERGY_COL: int = 13
DMFCC_COLS: tuple[int, ...] = tuple(range(15, 27))
DENERGY_COL: int = 27
ONSET_COL: int = 28
#: State numbers: MFCC 1-2 means, flux, energy mean, energy square deviation, low-energy
#: share, onset mean, onset square deviation, |d energy| mean, frames seen, previous beat
#: phase and log period, phase coherence, period jitter.
N_STATE: int = 14
#: Length of the packed parameters: statistics mean and std, W1, b1, w2, b2.
N_PARAMS: int = 2 * N_STATS + HIDDEN * N_STATS + HIDDEN + HIDDEN + 1


def pack(mean: np.ndarray, std: np.ndarray, w1: np.ndarray, b1: np.ndarray, w2: np.ndarray, b2: float) -> np.ndarray:
    """The detector's parameters as one float32 vector (:data:`N_PARAMS`,): statistics
    mean (N_STATS,), std (N_STATS,), W1 (HIDDEN, N_STATS), b1 (HIDDEN,), w2 (HIDDEN,), b2."""
    return np.concatenate([mean, std, np.ravel(w1), b1, w2, [b2]]).astype(np.float32)


def unpack(p: np.ndarray) -> tuple[np.ndarray, ...]:
    """Inverse of :func:`pack` (float64 arrays)."""
    p = np.asarray(p, np.float64)
    if p.shape != (N_PARAMS,):
        raise ValueError(f"presence parameters must have shape ({N_PARAMS},), got {p.shape}")
    s, h = N_STATS, HIDDEN
    i = 2 * s
    return p[:s], p[s:i], p[i: i + h * s].reshape(h, s), p[i + h * s: i + h * s + h], \
        p[i + h * s + h: i + h * s + 2 * h], p[-1:]


@njit(cache=True, nogil=True)
def presence_step(row, mfcc_mean, mfcc_std, dmfcc_std, ccol, scol, state, stats, a):  # pragma: no cover - compiled
    """Advance the statistics by one feature frame ``row`` (D,) with EMA coefficient ``a``
    (``ccol``: the pulse clarity's column; ``scol``: the steadiness column, -1: none, MFCC 1
    instead), in place: ``state`` (N_STATE,) float64, ``stats`` (N_STATS,) float64 (module
    docstring). The first frame starts the means at its values."""
    b = 1.0 - a
    first = state[9] == 0.0
    flux = 0.0
    for k in range(12):
        d = np.float64(row[15 + k]) / dmfcc_std[k]
        flux += d * d
    flux /= 12.0
    e = np.float64(row[13])
    o = np.float64(row[28])
    s0 = np.float64(row[scol]) if scol >= 0 else (np.float64(row[1]) - mfcc_mean[0]) / mfcc_std[0]
    if first:
        state[0] = s0
        state[1] = (np.float64(row[2]) - mfcc_mean[1]) / mfcc_std[1]
        state[2] = flux
        state[3] = e
        state[6] = o
    else:
        state[0] = a * state[0] + b * s0
        state[1] = a * state[1] + b * (np.float64(row[2]) - mfcc_mean[1]) / mfcc_std[1]
        state[2] = a * state[2] + b * flux
        state[3] = a * state[3] + b * e
        state[6] = a * state[6] + b * o
    dev = e - state[3]
    state[4] = a * state[4] + b * dev * dev
    state[5] = a * state[5] + b * (1.0 if dev < -10.0 else 0.0)
    od = o - state[6]
    state[7] = a * state[7] + b * od * od
    state[8] = a * state[8] + b * abs(np.float64(row[27]))
    clarity = 0.0
    if ccol >= 2 and ccol + 1 < row.shape[0]:
        clarity = np.float64(row[ccol])
        theta = math.atan2(np.float64(row[ccol - 1]), np.float64(row[ccol - 2]))
        logp = np.float64(row[ccol + 1])
        if not first:
            coh = math.cos(theta - state[10] - 2.0 * math.pi / (15.0 * 2.0 ** logp))
            ab = BEAT_A
            state[12] = ab * state[12] + (1.0 - ab) * coh
            state[13] = ab * state[13] + (1.0 - ab) * abs(logp - state[11])
        state[10] = theta
        state[11] = logp
    state[9] += 1.0
    stats[0] = state[0]
    stats[1] = state[1]
    stats[2] = math.log(state[2] + 1e-3)
    stats[3] = math.sqrt(state[4])
    stats[4] = state[5]
    stats[5] = state[6]
    stats[6] = math.log(state[7] + 1e-4)
    stats[7] = clarity
    stats[8] = state[3] / 10.0
    stats[9] = state[8]
    stats[10] = state[12]
    stats[11] = math.log(state[13] + 1e-3)


@njit(cache=True, nogil=True)
def presence_logit(stats, mean, std, w1, b1, w2, b2):  # pragma: no cover - compiled
    """The detector's logit (music > 0) for the statistics ``stats`` (N_STATS,)."""
    s = stats.shape[0]
    out = b2
    for h in range(w1.shape[0]):
        acc = b1[h]
        for i in range(s):
            acc += w1[h, i] * ((stats[i] - mean[i]) / std[i])
        out += w2[h] * math.tanh(acc)
    return out


@njit(cache=True, nogil=True)
def floor_range(ring, state, e):  # pragma: no cover - compiled
    """Push log energy ``e`` (dB) into ``ring`` (FLOOR_FRAMES,) float64 (NaN: not yet filled) at
    ``state[0]`` (the next slot, advanced in place) and return the ring's range (max - min, dB)."""
    i = int(state[0])
    ring[i] = e
    state[0] = (i + 1) % ring.shape[0]
    lo = e
    hi = e
    for k in range(ring.shape[0]):
        v = ring[k]
        if v == v:  # not NaN
            lo = min(lo, v)
            hi = max(hi, v)
    return hi - lo


@njit(cache=True, nogil=True)
def sound_cues(ring, ring_at, pause_e, pause_s, pause_at, e, s, out):  # pragma: no cover - compiled
    """One sounding frame's cues in one compiled call (log energy ``e`` dB, steadiness ``s``; NaN:
    no steadiness column): ``out[0]`` the :func:`floor_range` of ``ring``, ``out[1]`` the
    :func:`models.networks.voice_pauses.pause_steadiness` of ``pause_e``, ``pause_s`` (-inf without the
    column)."""
    out[0] = floor_range(ring, ring_at, e)
    out[1] = pause_steadiness(pause_e, pause_s, pause_at, e, s) if s == s else -np.inf


def _switch(part: str, doc: str, rule: str = "rule") -> property:
    """A gate attribute that reads and sets the switch ``rule`` of its composed ``part``."""
    return property(lambda g: getattr(getattr(g, part), rule), lambda g, on: setattr(getattr(g, part), rule, bool(on)),
                    doc=doc)


class MusicGate:
    """Frame-by-frame music presence: :meth:`step` takes one feature row (D,) and the
    performer's current state (dancing or not) and says whether this frame sounds like
    music (the caller counts frames before it changes state, :mod:`dance_stream`).

    feat_mean, feat_std: the model's feature standardisation (D,); params: the packed
    detector (:func:`pack`); energy_min: the silence threshold (log energy, dB); clarity_col:
    the pulse clarity's column (-1: none); steadiness_col: the steadiness column (the model's
    ``gate_col``; -1: none, statistic 0 is MFCC 1's mean); tau_music: the statistics' time
    constant (frames) while dancing (the model's ``gate_tau``); stop_params: the packed stop
    network that judges while dancing (the model's ``presence_stop``; None or all zeros:
    ``params`` in both states); voice_params: the packed voice network (the model's
    ``presence_voice``; None or all zeros: no voice-over rule); voice_rule: False switches the
    voice-over rule off, the pause rule and the start with it; pause_rule: False switches the pause
    rule off (module docstring; without a steadiness column there is none); start_rule: False
    switches the voice-over start off (an idle performer starts on its detector alone), the resume
    with it; resume_rule: False switches the resume off; fresh_rule: False keeps the statistics'
    time constant after a silence (module docstring); veto_rule: False lets an unsure stop network
    keep the dance whatever the voice network hears; context_rule: False switches the voice-over
    context off (module docstring). The attribute ``agree_rule`` (True) switches the three networks'
    agreement on an idle frame (module docstring); ``agreement.frames``, ``pauses.frames`` and
    ``voice_start.frames`` count the frames the agreement, the pause rule and the start heard as music;
    ``voiced`` says whether the voice-over start (trusted, ``false_start.py``) heard the last frame as music;
    ``lone`` is the lone voice (``lone_voice.py``: ``lone.rule`` switches it, ``lone.holding`` says the last
    frame holds the stop count); ``song_end`` the song's end (``song_end.py``: ``song_end.rule`` switches it);
    ``unsure`` the voice heard where the stop network wavers (``unsure_voice.py``).
    """

    def __init__(self, feat_mean: np.ndarray, feat_std: np.ndarray, params: np.ndarray, energy_min: float,
                 clarity_col: int, steadiness_col: int = -1, tau_music: float = TAU_MUSIC,
                 stop_params: np.ndarray | None = None, voice_params: np.ndarray | None = None,
                 voice_rule: bool = True, pause_rule: bool = True, start_rule: bool = True, resume_rule: bool = True,
                 fresh_rule: bool = True, veto_rule: bool = True, context_rule: bool = True) -> None:
        self._ccol = int(clarity_col)
        self._scol = int(steadiness_col)
        self._mfcc_mean = np.asarray(feat_mean, np.float64)[list(MFCC_COLS)]
        self._mfcc_std = np.asarray(feat_std, np.float64)[list(MFCC_COLS)]
        self._dmfcc_std = np.asarray(feat_std, np.float64)[list(DMFCC_COLS)]
        self._start = self._network(params)
        self.has_stop = stop_params is not None and bool(np.any(np.asarray(stop_params) != 0))
        self._stop = self._network(stop_params) if self.has_stop else self._start
        self.has_voice = voice_params is not None and bool(np.any(np.asarray(voice_params) != 0))
        self._voice = self._network(voice_params) if self.has_voice else self._start
        self.voice_rule = bool(voice_rule)
        self.fresh_rule = bool(fresh_rule)
        self.context_rule = bool(context_rule)
        self.voice_context = VoiceContext(release=self._scol >= 0)  # a voice heard over this dance before
        self.veto = Veto(self.has_voice, veto_rule)  # the voice network sure of no music (module docstring)
        self.agreement = Agreement(self.has_stop and self.has_voice)  # the three networks agree: an idle frame is music
        self.false_start = FalseStart()  # a dance the stop network never heard as music: false_start.py
        self.return_confirm = ReturnConfirm(self.has_voice)  # the voice network confirms a restart: return_confirm.py
        self.sharp_return = SharpReturn(self.has_stop and self.has_voice)  # one network's word on a return: sharp_return.py
        self.pauses = VoicePauses(pause_rule)  # the music heard in the voice's pauses (module docstring)
        self.lone = LoneVoice()  # no voice heard over a judged dance: a sure voice network overrules the pause rule
        self.song_end = SongEnd(round(tau_music), MARGIN_STOP)  # a song that stopped at once: song_end.py
        self.unsure = UnsureVoice()  # a voice heard where the stop network wavers: the context's evidence too
        self.voice_start = VoiceStart(start_rule, resume_rule)  # the voice-over start and the resume
        # bound once, not a frame: the callbacks, the pause rule's rings (sound_cues advances them)
        self._stop_z, self._voice_z, self._over = self._stop_logit, self._voice_logit, self._voice_over
        self._pause_e, self._pause_s, self._pause_at = self.pauses.ring_e, self.pauses.ring_s, self.pauses.ring_at
        self._ring = np.full(FLOOR_FRAMES, np.nan)  # the last sounding frames' log energy (dB)
        self._ring_at = np.zeros(1)
        self._cues = np.zeros(2)  # sound_cues' output
        self.energy_min = float(energy_min)
        self._a_music = math.exp(-1.0 / tau_music)
        self._a_idle = math.exp(-1.0 / TAU_IDLE)
        self._a_logit = math.exp(-1.0 / LOGIT_TAU) if LOGIT_TAU > 0 else 0.0
        self.reset()

    @staticmethod
    def _network(params: np.ndarray) -> tuple:
        """(mean, std, W1, b1, w2, b2) of packed parameters, as :func:`presence_logit` takes them."""
        mean, std, w1, b1, w2, b2 = unpack(params)
        return mean, np.maximum(std, 1e-6), w1, b1, w2, float(b2[0])

    def reset(self) -> None:
        self._state = np.zeros(N_STATE)
        self.stats = np.zeros(N_STATS)
        self.logit = 0.0  # the running mean of the detector's logit
        self._ring[:] = np.nan
        self._ring_at[0] = 0.0
        self.floor_db = 0.0  # the log energy's range over the last FLOOR_FRAMES sounding frames
        self.voice_frames = 0  # frames the voice-over rule kept as music
        self.voiced = False  # the voice-over start heard this (idle) frame as music
        self.detected = False  # the detector alone heard this (idle) frame as music
        self.pause_steady = -math.inf  # the steadiness in the voice's pauses (-inf: no steadiness column)
        self.silent = 0  # silent frames in a row
        self.fresh = 0  # sounding frames left at the idle time constant (after a silence)
        self.voice_context.reset()
        self.pauses.reset()
        self.voice_start.reset()
        self.veto.reset()
        self.agreement.reset()
        self.false_start.reset()
        self.lone.reset()
        self.song_end.reset()
        self.unsure.reset()
        self.return_confirm.reset()
        self.sharp_return.reset()

    def step(self, row: np.ndarray, dancing: bool) -> bool:
        """True when frame ``row`` (D,) sounds like music to a performer that is ``dancing``."""
        self.voiced = self.detected = self.lone.holding = False
        if float(row[ENERGY_COL]) <= self.energy_min:
            self.silent += 1
            self.song_end.silence()
            return False  # silence: the statistics wait for sound
        if self.silent >= FRESH_SILENCE and self.fresh_rule:
            self.fresh = FRESH_FRAMES  # after a silence: listen afresh
        self.return_confirm.sounding = 0 if self.silent >= FRESH_SILENCE else self.return_confirm.sounding + 1
        self.sharp_return.sound(self.silent >= FRESH_SILENCE)
        self.silent = 0
        fast = not dancing or self.fresh > 0
        self.fresh = max(0, self.fresh - 1)
        presence_step(row, self._mfcc_mean, self._mfcc_std, self._dmfcc_std, self._ccol, self._scol, self._state,
                      self.stats, self._a_idle if fast else self._a_music)
        z = presence_logit(self.stats, *(self._stop if dancing else self._start))
        a = self._a_logit if dancing else 0.0  # idle: the music's return is heard at once
        self.logit = a * self.logit + (1.0 - a) * z
        sound_cues(self._ring, self._ring_at, self._pause_e, self._pause_s, self._pause_at, float(row[ENERGY_COL]),
                   float(row[self._scol]) if self._scol >= 0 else math.nan, self._cues)
        self.floor_db, self.pause_steady = float(self._cues[0]), float(self._cues[1])
        self.agreement.has_danced = self.agreement.has_danced or dancing
        self.false_start.step(dancing, self.logit)
        self.song_end.step(dancing, self.logit)
        if not dancing:
            self.voice_context.step(False, True, False)  # the voice-over context runs on while idle, nothing kept
            if self.sharp_return.ends_break(self.agreement.has_danced):
                return True  # a long break's loud end: the music is back (sharp_return.py; no confirmation asked)
            if self.logit > MARGIN_START:
                self.detected = True
                return True
            voiced = self.voice_rule and self.voice_start.hears(self._over)  # its count runs on every such frame
            self.voiced = voiced and self.false_start.trusts()  # not after a false start (false_start.py)
            return self.voiced or self.agreement.hears(self.logit, self._stop_z, self._voice_z) or \
                self.sharp_return.hears(self.agreement.has_danced, FRESH_FRAMES, self._stop_z,
                                        self._voice_z)  # one network's word on a return
        if self.logit > -MARGIN_STOP:
            # the veto reaches 0 (VETO_TOP while a count runs): most frames of a song skip the call
            if (self.logit <= 0.0 or self.veto.counting) and self.veto.vetoes(self.logit, self.floor_db < FLOOR_DB,
                                                                               self._voice_z):
                self.voice_start.resume(False, self.voice_rule)
                self.voice_context.step(False, False, True)
                return False  # the stop network unsure, the voice network sure of no music: the veto
            if self.voice_start.evidence > 0.0:  # the resume's count runs down (most frames of a song skip the call)
                self.voice_start.resume(False, self.voice_rule)
            # a voice heard where the stop network wavers is evidence for the context (unsure_voice.py)
            self.voice_context.step(self.voice_rule and self.unsure.hears(self.logit, self._over), True, True)
            return True
        if self.voice_rule and self.song_end.ended(self.voice_context, self._voice_z):  # a host after a song (song_end.py)
            self.voice_start.resume(False, self.voice_rule)
            self.voice_context.step(False, False, True)
            return False
        # the music heard in the voice's pauses, unless a lone voice (lone_voice.py)
        if not (self.voice_rule and self.lone.pause_keeps(self.pauses, self.pause_steady, self.voice_context, self._voice_z)):
            if not (self.voice_rule and self._voice_over()):
                self.voice_start.resume(False, self.voice_rule)
                self.voice_context.step(False, False, True)
                return False
            self.voice_frames += 1  # a voice over the music: still music
        self.voice_start.resume(True, self.voice_rule)
        self.voice_context.step(True, True, True)
        return True

    def confirms_start(self, asks: bool) -> bool:
        """The dance may start on this idle frame heard as music (:mod:`models.networks.return_confirm`: a
        start of the detector's alone after the stream's first dance that the idle gate ``asks`` about, a
        restart or one without a rise in level, not right after a silence, waits for the voice network)."""
        asks = asks and not self.sharp_return.exempts(FRESH_FRAMES)  # right after a long break: the music's return
        return self.return_confirm.confirms(asks and self.detected and self.agreement.has_danced, self._voice_z,
                                            FRESH_FRAMES)

    def voice_holds(self) -> bool:
        """The voice-over context holds a dancing performer's stop on this frame
        (:meth:`models.networks.voice_context.VoiceContext.holds`; never with the voice-over rule or
        ``context_rule`` off)."""
        voice = self._voice_z if self.has_voice else None  # the release where it is sure of no music
        return self.voice_rule and self.context_rule and self.voice_context.holds(self.floor_db, self.pause_steady, voice)

    veto_rule = _switch("veto", "False switches the veto off (:attr:`models.networks.veto.Veto.rule`).")
    agree_rule = _switch("agreement", "False switches the three networks' agreement off "
                         "(:attr:`models.networks.agreement.Agreement.rule`).")
    pause_rule = _switch("pauses", "False switches the pause rule off (:attr:`models.networks.voice_pauses.VoicePauses.rule`).")
    start_rule = _switch("voice_start", "False switches the voice-over start off, the resume with it "
                         "(:attr:`models.networks.voice_start.VoiceStart.rule`).")
    unsure_rule = _switch("unsure", "False switches the unsure voice off: the context counts kept frames only "
                          "(:attr:`models.networks.unsure_voice.UnsureVoice.rule`).")
    resume_rule = _switch("voice_start", "False switches the resume off "
                          "(:attr:`models.networks.voice_start.VoiceStart.resume_rule`).", "resume_rule")

    def _voice_over(self) -> bool:
        """Both cues of the voice-over rule on this frame: the voice network hears music and the
        energy floor holds (module docstring)."""
        return self.has_voice and self.floor_db < FLOOR_DB and self._voice_logit() > -VOICE_MARGIN

    def _voice_logit(self) -> float:
        """The voice network's logit on the statistics of the last sounding frame."""
        return presence_logit(self.stats, *self._voice)

    def _stop_logit(self) -> float:
        """The stop network's logit on the statistics of the last sounding frame."""
        return presence_logit(self.stats, *self._stop)

    def voice_hears(self, margin: float) -> bool:
        """The voice network's logit on the statistics of the last sounding frame lies above ``-margin``
        (it hears some music under a voice; True without a voice network)."""
        return not self.has_voice or self._voice_logit() > -margin

    def stop_count(self) -> float:
        """Frames a dancing performer's frame that :meth:`step` heard as no music counts towards
        the stop: ``-logit / MARGIN_STOP`` within [1, :data:`SURE_COUNT`]. In silence the logit
        keeps its last value (the statistics wait), so silence right after music counts 1."""
        return min(SURE_COUNT, max(1.0, -self.logit / MARGIN_STOP))


def stats_trace(feats: np.ndarray, feat_mean: np.ndarray, feat_std: np.ndarray, clarity_col: int,
                tau: float, steadiness_col: int = -1) -> np.ndarray:
    """The statistics (T, N_STATS) of a feature sequence (T, D) at one time constant
    ``tau`` (frames), silence frames included (for fitting; the gate freezes on silence)."""
    g = MusicGate(feat_mean, feat_std, np.zeros(N_PARAMS, np.float32), -np.inf, clarity_col, steadiness_col)
    a = math.exp(-1.0 / tau)
    out = np.empty((len(feats), N_STATS))
    for t in range(len(feats)):
        presence_step(feats[t], g._mfcc_mean, g._mfcc_std, g._dmfcc_std, g._ccol, g._scol, g._state, out[t], a)
    return out

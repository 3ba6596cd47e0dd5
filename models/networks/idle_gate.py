"""The dancing performer's idle gate: is music playing, and how far is the performer faded to its idle.

:class:`IdleGate` reads one feature frame at a time (30 fps) and keeps a small state: whether
music plays (``music``), the frames the input has disagreed with that (``run``), the idle
weight (``w_idle``: 0 dancing, 1 idle; a smoothstep of it blends the pose,
:class:`models.networks.idle_fade.IdleFade`), the music's running level and the
length of the current break. Which frames sound like music is the detector's call:

* a model with a fitted presence detector (:class:`models.networks.music_gate.MusicGate`, the
  shipped one): its detector while idle, its stop network while dancing (a voice over the
  music kept as music by its voice network or by the music heard in the voice's pauses, the
  voice-over rule; an idle performer started by the voice network and the floor held 1.5 s,
  the voice-over start; a stop held ``voice_context.VOICE_HOLD`` frames where a voice was heard over
  the dance before, the voice-over context: :meth:`MusicGate.voice_holds`);
* an older one: the log frame energy above the model's silence threshold, and a logistic music
  detector on a 0.5-s running mean of the spectral shape (MFCC 1-12) and the beat tracker's
  pulse clarity (:data:`GATE_TAU_RETURN`, :data:`GATE_MARGIN`).

**Breaks are not the end of the music.** A frame at the model's silence threshold or
:data:`BREAK_DB` below the music's running level (:data:`LEVEL_TAU`) is a *break* frame. The
detector hears it as before (silence: its statistics wait; an audible quiet: they run, so a
reader's pauses between words still tell speech from music), but a dancing performer stops
only once the break has lasted :data:`BREAK_HOLD_SILENT` frames (silence: idle within 3 s of
its start) or :data:`BREAK_HOLD` (an audible quiet, crowd or room after a song: idle within
2.5 s). The stop-time breaks and breakdowns of a song (up to 2 s) are danced through, and
what a break danced through counted towards the stop is void when it ends. A break shorter than
``music_gate.FRESH_SILENCE`` frames (a pause between two words) voids only what it counted: the
count goes back to what it was before the break (``break_count``), so the words before it still
count (issue 43: an espeak-ng host after a song idle in 1.23 s instead of 1.40, applause at -35
dBFS after a song in 1.67 s instead of 1.87); a longer one voids the whole count (after it the
detector listens afresh: a song's stop-time break, DANCE_R_5 at 30 s, must not stop the dance on
the count of the fill before it). ``void_breaks_only=False``: every break voids the whole count.

**A song's start is danced** (issue 43: a song that begins under a voice, or with a quiet intro
the stop network hears as no music: sweetwaltz and nutcracker with the shared readers over them
at -6 dB stopped 1.3-1.9 s after they started). A start after :data:`SONG_IDLE` idle frames or
more (or at the stream's start) is a song's start: for :data:`SONG_DANCE` frames after it the
detector's stop is void (the count starts again) while the voice network is not sure there is no
music (its logit above ``-``:data:`SONG_MARGIN`, the veto's ``veto.VOICE_NO``, :meth:`MusicGate.voice_hears`;
without one, always): a false start on applause, noise or a host alone, where it is sure, stops as before.
A song's start the voice-over start made (``music_gate``: the voice network heard music under a held floor
for 1.5 s) is guarded while its logit lies above ``-``:data:`SONG_MARGIN_VOICED` (``voiced_song=False``:
as any other). A break
still stops it (silence idles within 3 s as ever). A restart sooner after a stop (a host the
detector took for music a moment) stops as before. The guard lasts as long as the voice-over context
needs dance before it may hold a stop (``voice_context.CONTEXT_FRAMES``, 10 s): with 5 s a song with a
voice over it from its first note was protected by neither from 5 to 10 s (fatswaller with the shared
readers at 0 dB stopped 9.2 s into its dance). ``song_start=False`` switches it off.

**A quiet return is no return** (issue 43: applause around the break threshold after a song). A
break that ends on a frame still :data:`RETURN_DB` or more under the music's level, which the
detector hears as no music, is not the music's return: the count keeps what the sound before the
break and the break's audible frames counted (only its silent frames are void), so sound that flickers across
:data:`BREAK_DB` under the level (sparse applause at -35 dBFS: breaks of 0.2-1 s, each voiding
the count) stops the dance as the detector says. ``quiet_return=False`` switches it off.

After :data:`ABSENT_FRAMES` frames without music (a sure detector's frame counting up to
twice, ``music_gate.SURE_COUNT``; a frame the pause rule keeps for a lone voice holds the count, neither
counting nor clearing it: ``lone_voice.py``) the performer fades over :data:`FADE_FRAMES` into the idle;
after ``music_gate.START_FRAMES`` (:data:`PRESENT_FRAMES` with the logistic detector) frames
of music it fades back. ``forced_idle`` holds the idle whatever the music (the show's
``/performer/idle``).
"""

from __future__ import annotations

import math

import numpy as np

from models.networks.dance_jit import gate_ema
from models.networks.dance_vq import GATE_MFCC, GATE_TAU, DanceVQ
from models.networks.music_gate import ENERGY_COL, FRESH_SILENCE, START_FRAMES, MusicGate
from models.networks.veto import VOICE_NO
from models.networks.voice_context import CONTEXT_FRAMES

#: Frames without music before the performer starts to settle (0.5 s; with the presence
#: detector a frame it is sure of counts up to twice, ``music_gate.SURE_COUNT``: 0.27 s).
ABSENT_FRAMES: int = 15
#: Frames of music before it starts to dance again (0.2 s; the logistic detector's).
PRESENT_FRAMES: int = 6
#: Frames of the crossfade between dance and idle (0.53 s), eased with a smoothstep.
FADE_FRAMES: int = 16
#: Time constant (frames) of the logistic detector's running mean while no music is heard:
#: shorter than the one it was fitted with (GATE_TAU, 0.5 s), so the dance comes back within a second.
GATE_TAU_RETURN: float = 5.0
#: Logit margin of the logistic detector while music is playing: quiet or pulse-less passages
#: of a song must look clearly like noise before the performer stops dancing.
GATE_MARGIN: float = 6.0
#: A frame this many dB (log frame energy) below the music's running level is a break frame.
#: On the shared recordings and the validation songs, played whole, no run of such frames
#: lasts 1 s (the longest 0.7 s, DANCE_C_2); at 15 dB runs of 0.8-1.2 s appear
#: (benchmarks/studies/idle_gate.py --breaks).
BREAK_DB: float = 20.0
#: Time constant (frames) of the music's running level (log frame energy, dB), taken over the
#: frames that are not break frames (2 s).
LEVEL_TAU: float = 60.0
#: Frames of silence (every frame at the silence threshold) after which a dancing performer
#: stops (2.33 s: with the fade, idle 2.87 s after the music stops; a 2-s break danced through).
BREAK_HOLD_SILENT: int = 70
#: Frames of an audible break (some frame above the silence threshold, all 20 dB under the
#: music) after which it stops (1.93 s: idle 2.47 s after the music gave way to a quiet crowd
#: or room; a stop-time break of a second or so danced through).
BREAK_HOLD: int = 58
#: A song's start (module docstring): a start after this many idle frames or more (5 s, or the
#: stream's start) dances at least SONG_DANCE frames unless a break stops it. The idle: a host's
#: false restarts come within 5 s of the stop (docs/history-listening.md, issue 43). The dance: until the
#: voice-over context may hold a stop (voice_context.CONTEXT_FRAMES, 10 s), not tuned (at 5 s a song
#: under a voice from its start was left unguarded for 5 s; 9 s reads as 5 on every part, 12.5 s as
#: 10: docs/presence.md, idle_gate.py --song-dance 270 / 375).
SONG_IDLE: int = 150
SONG_DANCE: int = CONTEXT_FRAMES
#: A song's start is guarded while the voice network's logit lies above -SONG_MARGIN: not sure there is no
#: music, the veto's threshold (veto.VOICE_NO, 4), not tuned. At MARGIN_STOP (2), before the false start's
#: doubt (false_start.py), nutcracker's quiet intro under the readers stopped (0 / -6 dB: 3.7 / 1.6 % idle;
#: 3.4 / 0.8 % at 4), and at 4 without the doubt an espeak-ng host from a stream's start danced 53.6 % of
#: 30 s instead of 45.3 (the voice-over start restarting what the guard held); at 5 a stream's false
#: starts on pink noise and a host lasted longer (docs/history-listening.md, idle_gate.py --song-margin).
SONG_MARGIN: float = VOICE_NO
#: A song's start the voice-over start made (the voice network heard music under a held floor for 1.5 s,
#: voice_start.START_EVIDENCE) is guarded while its logit lies above -SONG_MARGIN_VOICED: that evidence
#: outweighs a moment's doubt. Three times MARGIN_STOP, not tuned: 5, 8 and inf read the same on every
#: part (nutcracker's intro under the readers at 0 dB: 3.4 -> 1.2 % idle); a start of the detector's keeps
#: SONG_MARGIN, where 5 lengthened false starts on pink noise and a host (docs/history-listening.md,
#: idle_gate.py --song-margin-voiced).
SONG_MARGIN_VOICED: float = 6.0
#: The quiet return (module docstring): a break that ends on a frame still this many dB or more
#: under the music's level, heard as no music, voids only what its silent frames counted towards
#: the stop. Half of BREAK_DB, a round figure, not tuned (docs/presence.md).
RETURN_DB: float = 10.0


class IdleGate:
    """Music present or not, and the idle weight, one feature frame at a time (module docstring).

    model: the dance_vq model whose gate runs (its ``presence``/``presence_stop`` networks, or
    its logistic ``gate``/``gate_w``); feat_mean, feat_std: its feature standardisation (D,);
    hold_breaks: False judges break frames by the detector like any other (as before breaks
    were held: silence stopped after :data:`ABSENT_FRAMES`); voice_rule: False hears a voice
    over the music as the stop network does (``music_gate.MusicGate``'s voice-over rule off;
    ``presence.voice_rule`` switches it on a running gate); void_breaks_only: False voids the
    whole count when any break is danced through; song_start: False lets the detector stop a song's
    start at once; quiet_return: False voids a break's count on any frame that ends it (module docstring).
    The attribute ``voiced_song`` (True) guards a song's start the voice-over start made at
    :data:`SONG_MARGIN_VOICED`, not :data:`SONG_MARGIN`.

    State (``reset``): ``music`` (bool), ``run`` (frames of disagreement, weighted),
    ``w_idle`` (0..1), ``level`` (dB), ``break_frames`` (the current break's length),
    ``break_silent`` (every frame of it silent), ``break_count`` (``run`` as the break began),
    ``break_kept`` (the count a quiet return keeps: ``run`` before the break and what its audible frames
    heard as no music counted since a frame of it was last heard as music),
    ``idle_frames`` (frames idle in a row), ``danced`` (frames since a song's start, capped at
    SONG_DANCE), ``voiced`` (the voice-over start made the last start), ``forced_idle``.
    """

    def __init__(self, model: DanceVQ, feat_mean: np.ndarray, feat_std: np.ndarray, hold_breaks: bool = True,
                 voice_rule: bool = True, void_breaks_only: bool = True, song_start: bool = True,
                 quiet_return: bool = True) -> None:
        c = model.config
        self.quiet_return = bool(quiet_return)
        self.hold_breaks = bool(hold_breaks)
        self.song_start = bool(song_start)
        self.voiced_song = True  # a song's start the voice-over start made: guarded at SONG_MARGIN_VOICED
        self.void_breaks_only = bool(void_breaks_only)
        self.energy_min, self._gate_b = (float(v) for v in model.gate)
        self._ecol = c.energy_col if 0 <= c.energy_col < c.feature_dim else None
        self._gcols = [*GATE_MFCC, c.clarity_col] if 0 <= c.clarity_col < c.feature_dim else []
        self._gate_idx = np.array(self._gcols, np.int64)  # (G,) the logistic detector's feature columns
        self._gate_w = model.gate_w.numpy().astype(np.float64)[: len(self._gcols)]
        self._gate_mean = np.asarray(feat_mean, np.float64)[self._gcols]
        self._gate_std = np.asarray(feat_std, np.float64)[self._gcols]
        self._gate_a = math.exp(-1.0 / GATE_TAU)
        self._gate_a_return = math.exp(-1.0 / GATE_TAU_RETURN)
        self._level_a = math.exp(-1.0 / LEVEL_TAU)
        fitted = bool(model.presence.abs().sum() > 0) and self._ecol == ENERGY_COL  # else the logistic detector
        self.presence = MusicGate(feat_mean, feat_std, model.presence.numpy(), self.energy_min, c.clarity_col,
                                  c.gate_col, c.gate_tau, model.presence_stop.numpy(), model.presence_voice.numpy(),
                                  voice_rule) if fitted else None
        self.forced_idle = False
        self.reset()

    def reset(self) -> None:
        """A stream's start: no music, fully idle, no level heard yet."""
        self.music = False
        self.run = 0.0  # frames the input has disagreed with ``music`` (weighted: SURE_COUNT)
        self.w_idle = 1.0  # 1 = idle, 0 = dancing; a stream starts at rest and fades in on music
        self.level = math.nan  # the music's running level, dB (NaN: nothing heard yet)
        self.break_frames = 0
        self.break_silent = True
        self.break_count = 0.0  # ``run`` as the current break began
        self.break_kept = 0.0  # the count a quiet return keeps (all but what the break's silent frames counted)
        self.idle_frames = SONG_IDLE  # frames idle in a row: a stream's first start is a song's start
        self.danced = SONG_DANCE  # frames since a song's start (SONG_DANCE: none to protect)
        self.voiced = False  # the voice-over start made the last start
        self.present = False  # the detector's verdict on the last frame
        self._ema = np.zeros(len(self._gcols))  # the logistic detector's running mean
        if self.presence is not None:
            self.presence.reset()

    def heard(self) -> str:
        """What the last frame sounded like, in words for the show desk: ``"silence"`` or ``"quiet"``
        (a break: silent, or BREAK_DB under the music's level), ``"music"``, or ``"not music"``
        (sound the detector does not take for music: a voice, noise)."""
        if self.break_frames:
            return "silence" if self.break_silent else "quiet"
        return "music" if self.present else "not music"

    def _is_break(self, energy: float) -> bool:
        """Frame energy ``energy`` (dB) is a break frame: silence, or :data:`BREAK_DB` under the
        running level. Updates the level with the frames that are not, and the break's length."""
        silent = energy <= self.energy_min
        if not silent and not energy < self.level - BREAK_DB:  # NaN level: nothing to be under yet
            a = 0.0 if math.isnan(self.level) else self._level_a
            self.level = a * self.level + (1.0 - a) * energy if a else energy
            self.break_frames, self.break_silent = 0, True
            return False
        self.break_frames += 1
        self.break_silent = self.break_silent and silent
        return True

    def _detector(self, row: np.ndarray) -> bool:
        """The detector's verdict on a frame that is not a break: sounds like music."""
        if self.presence is not None:  # the presence detector (models/networks/music_gate.py)
            return self.presence.step(row, self.music)
        if self._ecol is not None and row[self._ecol] <= self.energy_min:
            return False  # silence: the detector's running mean waits for sound
        if self._gcols:  # noise without music: the logistic detector on the running mean
            a = self._gate_a if self.music else self._gate_a_return
            gate_ema(row, self._gate_idx, self._gate_mean, self._gate_std, self._ema, a)  # in place, compiled
            # hysteresis: while dancing, noise must be clearly noise (logit below -GATE_MARGIN)
            if float(self._ema @ self._gate_w) + self._gate_b <= (-GATE_MARGIN if self.music else 0.0):
                return False
        return True

    def step(self, row: np.ndarray) -> float:
        """Advance by one feature frame ``row`` (D,); the idle weight after it (0 dancing, 1 idle)."""
        held = False
        energy = float(row[self._ecol]) if self._ecol is not None else math.inf  # log frame energy, dB
        was_break = self.break_frames
        if self.hold_breaks and self._ecol is not None:
            was = self.break_frames
            if not was:
                self.break_count = self.break_kept = self.run
            if self._is_break(energy):
                held = self.music and self.break_frames < (BREAK_HOLD_SILENT if self.break_silent else BREAK_HOLD)
            elif was and self.music:  # a break danced through: what it counted towards the stop is void
                self.run = self.break_count if self.void_breaks_only and was < FRESH_SILENCE else 0.0
                if self.quiet_return and energy < self.level - RETURN_DB:  # a quiet return: all but what its silent
                    self.run = max(self.run, self.break_kept)  # frames counted stays
        if self.presence is not None:
            self.presence.veto.counting = self.music and self.run > 0.0  # the veto's reach (veto.VETO_TOP)
            ended = not self.music and was_break >= BREAK_HOLD and not self.break_frames  # a long break: the music gone
            self.presence.sharp_return.see(energy >= self.level + RETURN_DB, bool(self.break_frames), ended,
                                           energy >= self.level - RETURN_DB)  # at the music's level: sharp_return.py
        present = self._detector(row)
        self.present = present
        if self.music and not present and not self.break_frames and self.presence is not None:
            held = held or self.presence.voice_holds()  # a voice heard over this dance before: voice_context.VOICE_HOLD
        count = 1.0  # a sure detector counts a frame as more than one (music_gate.SURE_COUNT)
        if self.music and not present and self.presence is not None:
            count = self.presence.stop_count()
        if self.break_frames and self.music and energy > self.energy_min:  # an audible break frame: music clears,
            self.break_kept = 0.0 if present else self.break_kept + count  # no music counts
        hold = self.music and present and self.presence is not None and self.presence.lone.holding  # lone_voice.py
        self.run = self.run + count if present != self.music else (self.run if hold else 0.0)
        start = PRESENT_FRAMES if self.presence is None else START_FRAMES  # the presence detector's own
        self.idle_frames = 0 if self.music else self.idle_frames + 1
        self.danced = min(SONG_DANCE, self.danced + 1)
        due = self.run >= (start if present else ABSENT_FRAMES) and not held and present != self.music
        asks = self.idle_frames < SONG_IDLE or not energy >= self.level + RETURN_DB  # a restart, or no rise (NaN: none)
        if due and present and self.presence is not None and not self.presence.confirms_start(asks):
            due = False  # the voice network confirms a restart (return_confirm.py): the count runs on
        if due:
            protect = self.song_start and self.danced < SONG_DANCE and not self.break_frames
            margin = SONG_MARGIN_VOICED if self.voiced else SONG_MARGIN
            if present or not (protect and (self.presence is None or self.presence.voice_hears(margin))):
                if present:  # a start after SONG_IDLE idle frames is a song's start: danced SONG_DANCE frames
                    self.danced = 0 if self.idle_frames >= SONG_IDLE else SONG_DANCE
                    self.voiced = self.voiced_song and self.presence is not None and self.presence.voiced
                self.music, self.run = present, 0.0
            else:
                self.run = 0.0  # a song's start: the detector's stop is void, the count starts again
        target = 1.0 if (self.forced_idle or not self.music) else 0.0
        step = 1.0 / FADE_FRAMES
        self.w_idle = min(target, self.w_idle + step) if target > self.w_idle else max(target, self.w_idle - step)
        return self.w_idle

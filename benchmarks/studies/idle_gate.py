"""Knowing when music plays: where a dance_vq performer dances, settles and dances again.

Two parts, both through the model's live stream (:class:`models.networks.dance_stream.DanceStream`,
features as the engine computes them):

* **Recordings** (``--music``, default ../shared/data/music, and the validation songs of
  ``--data``): each whole recording alone; ``idle``: the share of its frames after the first
  3 s in which the performer is not fully dancing (idle weight above 0; target at most 0.02);
  ``idle_sounding``: the same up to the end of its music: its last sound (many end in 1-6 s
  of silence, where the performer is to idle: ``models.evaluation.listening.sounding_frames``)
  or, for a live recording that goes on with applause, where the music stops
  (``models.evaluation.listening.MUSIC_ENDS_S``).
  Only the gate runs here (:meth:`DanceStream.listen`: the idle weight depends on the
  features alone).
* **Between songs**: validation song, gap, the next validation song (20 s of each, from a
  third into the song), for gaps of silence, applause (-20 and -35 dBFS), crowd babble
  (-30, -45), room tone (-45, -60), pink noise (-30) and read speech (``--speech``, each
  recording at the RMS level of the song before it), made by
  :mod:`models.training.music_gate` with other seeds than its fit (dBFS: RMS level). Per gap:
  ``settle_s``, seconds from the gap's start to the performer fully idle (target at most 2);
  ``held``, the share of the gap's frames after that in which it stays fully idle (target 1);
  ``back_s``, seconds from the music's return to fully dancing (target at most 1);
  ``max_step_deg``, the largest frame-to-frame bone rotation during both fades, against the
  dance's own (no snap); ``idle_step_deg``, the largest while fully idle (calm). The full
  stream runs (poses too).

* **Voices and breaks** (``--music`` only; issue 43): each recording with the ``--speech``
  recordings (strung together, looped) laid over it at 0 and -6 dB relative to its RMS level
  (a rapper or a host over the track: still music; ``--voice-from S``: from S s on, after an
  instrumental start), and with its audio cut to silence for 1 s
  and for 2 s every 10 s (stop-time breaks); ``idle_sounding`` of each (target at most 0.02).
  The between-songs targets of issue 43: silence idle within 3 s (a song's 2-s break is
  danced through), speech within 2 s, crowd and noise within 2.5 s.

* **Readers after each recording** (``--parts readers``, not in the default): 20 s from a third
  (``--reader-at``: another share) into each ``--music`` recording, each ``--speech`` recording at its RMS level, the next
  recording; settle, held and back as between songs (speech alone: idle within 2 s).

* **espeak-ng voices over and after training songs** (``--parts espeak``, not in the default;
  the material the voice-over rule's constants were chosen on, not the judging readers): 60 s of
  each of :data:`ESPEAK_SONGS` training songs (a third in) with an espeak-ng host
  (``models.training.music_gate.speech``: reverberation, a noise bed) over it at 0 and -6 dB,
  idle as for the mixes, and over the song's first 30 s (its start under a host, ``from its start``);
  and each song's 20 s, 10 s of a host at its level, the next song:
  settle, held and back as between songs, two hosts per song.

* **The stretches a hold would have to bridge** (``--parts stretches``, not in the default; issue
  43's voices over the music): each mix of the voices part with the dancing performer never
  stopping (a stop the gate decides is undone, the gate's state and statistics otherwise as they
  run): the runs of frames in which its detector and the voice-over rule hear no music (break
  frames count as heard). Per mix the longest run (s) and where it starts, the music's and the
  voice's level over it (dBFS), and how many runs last :data:`STRETCH_MIN` frames or more (a
  sure stop's count): a hold that keeps the dance through every run must outlast the longest,
  and it delays a voice alone after a song (``--parts readers``) by as much.

* **No music from the stream's start** (``--parts leadin``, not in the default): each ``--speech``
  recording and :data:`LEADIN_HOSTS` espeak-ng hosts of 30 s at -20 dBFS, and each kind of gap but
  silence (30 s), through a fresh stream, nothing heard before: the share of frames not fully idle
  (target 0; a false start the detector makes on them, which the song's start must not lengthen) and
  the longest false start (s from its first frame to fully idle again: issue 43 asks 2 s for a voice, 2.5 s
  for noise), at the study's draw and, for the noises and hosts, at :data:`LEADIN_DRAWS` other draws
  (``--leadin-draws``: median and worst); and each case's first :data:`LEADIN_THEN_S` s followed by a
  validation song: back (s) from the song's start to fully dancing (the stream's first song after noise).

* **A voice over a song's end, going on alone** (``--parts talkover``, not in the default): 20 s of each
  ``--music`` recording (from ``--reader-at``) with the ``--speech`` recordings over it at each of
  :data:`MIX_DB`, the voice going on alone :data:`TALKOVER_S` s after the music stops (a DJ talking
  over a track's end): seconds from the music's end to fully idle (speech alone: within 2 s; what
  the voice-over context's hold would cost without its release where the music is gone).

``--parts`` picks the parts (default ``recordings,mixes,gaps``). ``--floor-db`` and
``--voice-margin`` set the voice-over rule's ``music_gate.FLOOR_DB`` and ``VOICE_MARGIN`` (``inf``:
that cue always holds; ``--floor-db 0``: the voice network's part off), ``--pause-steady`` its pause
rule's ``voice_pauses.PAUSE_STEADY`` (``inf``: off; with ``--floor-db 0`` the whole rule off), ``--start-evidence``
and ``--start-decay`` its voice-over start's ``voice_start.START_EVIDENCE`` (``inf``: off) and ``START_DECAY``,
``--voice-hold``, ``--gone-floor-db``, ``--gone-steady`` and ``--gone-voice`` the voice-over context's hold and its
release (``voice_context.VOICE_HOLD``, ``GONE_FLOOR_DB``: ``inf``, never released; ``GONE_STEADY``, ``GONE_VOICE``),
``--voice-no`` the veto's threshold (``veto.VOICE_NO``), ``--veto-top`` and ``--voice-no-run``
its reach and threshold while a stop count runs (``VETO_TOP``, ``VOICE_NO_RUN``; ``--veto-top 0
--voice-no-run 4``: as when none runs), ``--agree-stop`` and ``--agree-voice`` the stop and voice networks'
thresholds of the three networks' agreement on an idle frame (``agreement.AGREE_STOP``, ``AGREE_VOICE``),
``--song-dance`` the frames a song's start is danced (``idle_gate.SONG_DANCE``) and ``--song-margin`` the
voice network's margin that guards it (``idle_gate.SONG_MARGIN``; ``--song-margin-voiced``:
``SONG_MARGIN_VOICED``, where the voice-over start made the start), to measure its parts
alone; ``--off`` switches off the parts that have no constant to set:
``break-count`` (a break danced through voids the whole stop count, as before issue 43's slow
settles), ``fresh`` (the statistics keep their time constant after a silence), ``resume`` (the
voice-over start's count starts from 0 when a voice stops the dance), ``song-start`` (the detector may
stop a song's start at once: ``idle_gate.SONG_DANCE``), ``quiet-return`` (a break's end voids its count
even on a frame still ``idle_gate.RETURN_DB`` under the music, heard as no music), ``veto`` (the voice
network no longer overrules an unsure stop network: ``veto.VOICE_NO``), ``context`` (a voice heard
over the dance before does not hold its stop: ``voice_context.VOICE_HOLD``), ``agree`` (an idle performer
starts on its detector over ``music_gate.MARGIN_START`` only, not where the three networks agree),
``false-start`` (the voice-over start may start the dance again after a dance the stop network never
heard as music: ``false_start.CONFIRM_FRAMES``, which ``--confirm-frames`` sets, with ``--resume-frames``
its ``RESUME_FRAMES``), ``voiced-song`` (a song's start the voice-over start made is guarded at
``idle_gate.SONG_MARGIN`` as any other, not ``SONG_MARGIN_VOICED``), ``lone-voice`` (the pause rule keeps a
frame whatever the voice network hears in a dance the voice-over context heard no voice over:
``lone_voice.py``), ``return-confirm`` (after the stream's first dance the detector starts the dance without the
voice network: ``return_confirm.CONFIRM_VOICE``, which ``--confirm-voice`` sets), ``unsure-voice`` (the
voice-over context counts only its rules' kept frames, not a voice heard where the stop network wavers:
``unsure_voice.UNSURE_TOP``, which ``--unsure-top`` sets), ``host`` (the voice-over and pause rules keep a host's
words after a song that stopped at once: ``song_end.py``). ``--trace`` prints the gate's
state frame by frame at each stop of a recording with the readers over it, through a reader
after a recording and the next recording's start, or through a gap between songs and the music's
return (``gap:LABEL``), or through an espeak-ng host after a training song (``espeak:SONG/K``),
or through a case of ``--parts leadin`` from the stream's start (``leadin:CASE``; a recording with
the readers, ``RECORDING@DB``, with them from ``--voice-from`` s), instead of the tables (which network or rule said what).

It also prints the gate's own cost per frame (median and 99th percentile, microseconds).

``--plot`` draws the idle weight over the between-songs programmes.

    .venv/bin/python benchmarks/studies/idle_gate.py --checkpoint models/assets/default.pt \\
        --data ../shared/data/dwm --plot docs/img/presence_gate.png
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from models.data.split import VAL_DANCES
from models.evaluation.listening import bone_steps_deg, music_end

#: (label, kind, dBFS) of the gaps; dBFS None: speech at the level of the song before it.
GAPS: tuple[tuple[str, str, float | None], ...] = (
    ("silence", "silence", None), ("applause -20", "applause", -20.0), ("applause -35", "applause", -35.0),
    ("crowd -30", "crowd", -30.0), ("crowd -45", "crowd", -45.0), ("room -45", "room", -45.0),
    ("room -60", "room", -60.0), ("pink -30", "pink", -30.0))
SR = 22050
HOP = 735
#: The log energy's feature column (dB).
ENERGY = 13
#: Levels (dB relative to the recording's RMS) of the speech laid over each recording.
MIX_DB: tuple[float, ...] = (0.0, -6.0)
#: Lengths (s) of the silences cut into each recording, one every :data:`BREAK_EVERY_S`.
BREAKS_S: tuple[float, ...] = (1.0, 2.0)
BREAK_EVERY_S: float = 10.0
#: Training songs (drawn with :data:`ESPEAK_SEED`) under and before the espeak-ng hosts of ``--parts espeak``.
ESPEAK_SONGS: int = 8
ESPEAK_SEED: int = 4343
#: Seconds the readers of ``--parts talkover`` go on alone after the music stops.
TALKOVER_S: float = 8.0
#: espeak-ng hosts and the seed of ``--parts leadin`` (the seed of its noises too).
LEADIN_HOSTS: int = 6
LEADIN_SEED: int = 99
#: Other draws of ``--parts leadin``'s noises and hosts (seeds 0 to this - 1, ``--leadin-draws``): one draw
#: hid crowd -30's false starts (0 % at LEADIN_SEED).
LEADIN_DRAWS: int = 8
#: Seconds of each ``--parts leadin`` case before a song (its "then a song" column: a show that opens on
#: noise or a host, then its first song).
LEADIN_THEN_S: float = 8.0
#: Frames of no music that can stop a dancing performer (``idle_gate.ABSENT_FRAMES`` 15 over
#: ``music_gate.SURE_COUNT`` 2): ``--parts stretches`` counts the runs as long as this.
STRETCH_MIN: int = 8
#: Most seconds to fully idle per kind of gap (issue 43): silence 3, speech 2, the rest 2.5.
SETTLE_TARGET_S: dict[str, float] = {"silence": 3.0, "speech": 2.0}
SETTLE_TARGET_OTHER_S: float = 2.5


#: Parts of the gate ``--off`` switches off: name -> (``IdleGate``, its ``MusicGate`` or a part that one composes
#: (``false_start``, ``lone``, ``return_confirm``, ``unsure``, ``sharp_return``, ``song_end``), attribute).
SWITCHES: dict[str, tuple[str, str]] = {"break-count": ("idle", "void_breaks_only"), "fresh": ("presence", "fresh_rule"),
                                        "resume": ("presence", "resume_rule"), "song-start": ("idle", "song_start"),
                                        "quiet-return": ("idle", "quiet_return"), "veto": ("presence", "veto_rule"),
                                        "context": ("presence", "context_rule"),
                                        "agree": ("presence", "agree_rule"), "false-start": ("false_start", "rule"), "lone-voice": ("lone", "rule"),
                                        "voiced-song": ("idle", "voiced_song"), "return-confirm": ("return_confirm", "rule"),
                                        "unsure-voice": ("unsure", "rule"), "sharp-return": ("sharp_return", "rule"),
                                        "host": ("song_end", "rule")}
#: The switches ``--off`` named (set by main).
OFF: set[str] = set()


def new_stream(lm, seed: int):
    """A fresh :class:`DanceStream` of ``lm`` with the gate's parts named in :data:`OFF` switched off."""
    from models.networks.dance_stream import DanceStream

    stream = DanceStream(lm.model, seed=seed)
    for name in OFF:
        where, attr = SWITCHES[name]
        part = stream._idle if where == "idle" else stream._idle.presence
        if part is not None and where in ("false_start", "lone", "return_confirm", "unsure", "sharp_return",
                                          "song_end"):  # a part the MusicGate composes
            part = getattr(part, where)
        if part is not None:
            setattr(part, attr, False)
    return stream


def trace(lm, feats: np.ndarray, windows: list[tuple[int, int]]) -> list[str]:
    """The gate's state frame by frame (a fresh stream on ``feats`` (T, D), :data:`OFF` applied) over
    each (first, last) frame window: time (s), idle weight, music (the gate's state), heard (the
    detector's verdict), the stop or start logit (running mean), the stop network's own, the voice network's logit, the
    floor (dB range over 1 s), the pauses' steadiness, kept by the voice-over (V) or pause (P) rule
    or heard as music by the three networks' agreement (A) or the voice-over start held back by a false
    start's doubt (D) or not kept by the pause rule for a lone voice (L, ``lone_voice.py``) or a detector's start
    held back until the voice network confirms it (C) or a voice heard where the stop network wavers
    (U, ``unsure_voice.py``: evidence for the voice-over context) or heard as music by one network on a sharp return
    (R, ``sharp_return.py``) or not kept by the voice-over and pause rules after a song's end (E, ``song_end.py``),
    the stop count, the break's frames, the log
    energy (dB), the voice-over context (frames kept 10 s to 2.5 s ago: ``voice_context.CONTEXT_MIN`` holds
    the stop), and three statistics: the log energy's spread (dB), the pulse clarity, the beat phase's
    coherence. An empty window: every stop of the
    dance after 3 s, from 1.5 s before it to its return."""
    from models.networks.music_gate import presence_logit

    stream = new_stream(lm, 7)
    ig, pg = stream._idle, stream._idle.presence
    if pg is None:
        return ["(no presence detector: nothing to trace)"]
    rows, music = [], []
    for t in range(len(feats)):
        kv, kp, ka, kd = pg.voice_frames, pg.pauses.frames, pg.agreement.frames, pg.false_start.frames
        kl, kc, ku, kr = pg.lone.frames, pg.return_confirm.frames, pg.unsure.frames, pg.sharp_return.frames
        ke = pg.song_end.frames
        w = ig.step(np.asarray(feats[t], np.float32))
        vz = presence_logit(pg.stats, *pg._voice) if pg.has_voice else float("nan")
        sz = presence_logit(pg.stats, *pg._stop)
        kept = ("V" if pg.voice_frames > kv else "P" if pg.pauses.frames > kp else "A" if pg.agreement.frames > ka
                else "D" if pg.false_start.frames > kd else "L" if pg.lone.frames > kl
                else "C" if pg.return_confirm.frames > kc else "U" if pg.unsure.frames > ku
                else "R" if pg.sharp_return.frames > kr else "E" if pg.song_end.frames > ke else "-")
        music.append(ig.music)
        rows.append(f"{t / 30:7.2f} {w:4.2f} {int(ig.music)} {int(ig.present)} {pg.logit:6.2f} {sz:6.2f} {vz:6.2f} {pg.floor_db:5.1f} "
                    f"{pg.pause_steady:5.2f} {kept} {ig.run:5.2f} {ig.break_frames:3d} {float(feats[t][ENERGY]):6.1f} {pg.voice_context.count:3d}"
                    f" {pg.stats[3]:5.1f} {pg.stats[7]:4.2f} {pg.stats[10]:4.2f}")
    if windows == [(0, 0)]:
        windows = []
        for t in range(91, len(music)):
            if music[t - 1] and not music[t]:
                back = next((u for u in range(t, len(music)) if music[u]), len(music) - 1)
                windows.append((max(0, t - 45), min(len(music) - 1, back + 6)))
    head = "      s    w m h  logit   stop  voice floor pause k count brk    dB ctx  sprd clar  coh"
    return [line for a, b in windows for line in [f"-- frames {a}-{b}", head, *rows[a: b + 1]]]


def rms_dbfs(x: np.ndarray) -> float:
    return float(20 * np.log10(np.sqrt(np.mean(np.square(x, dtype=np.float64))) + 1e-12))


def gap_audio(kind: str, seconds: float, dbfs: float | None, rng: np.random.Generator, pool: list[np.ndarray]) -> np.ndarray:
    from models.training import music_gate as mg

    if kind == "silence":
        return np.zeros(int(seconds * SR), np.float32)
    if kind == "applause":
        return mg.applause(seconds, rng, pool, dbfs)
    if kind == "crowd":
        return mg.babble(seconds, rng, pool, dbfs)
    if kind == "room":
        return mg.room(seconds, rng, pool, dbfs)
    return mg.plain_noise(seconds, rng, kind, dbfs)


def with_speech(audio: np.ndarray, speech: np.ndarray, db: float, sound: int, from_s: float = 0.0) -> np.ndarray:
    """``audio`` (n,) with ``speech`` looped over it from ``from_s`` seconds on at ``db`` dB relative to
    the RMS of its first ``sound`` frames (its music, without a silent end)."""
    k = min(len(audio), int(round(from_s * SR)))
    talk = np.zeros(len(audio), speech.dtype)
    talk[k:] = np.resize(speech, len(audio) - k)
    gain = 10 ** ((rms_dbfs(audio[: sound * HOP]) - rms_dbfs(speech) + db) / 20)
    return (audio + gain * talk).astype(np.float32)


def with_breaks(audio: np.ndarray, seconds: float, every: float = BREAK_EVERY_S) -> np.ndarray:
    """``audio`` (n,) with ``seconds`` of silence cut in (the audio replaced) every ``every`` s from
    ``every`` s on: a song's stop-time breaks."""
    out = audio.copy()
    for t0 in np.arange(every, len(out) / SR - seconds, every):
        out[int(t0 * SR): int((t0 + seconds) * SR)] = 0.0
    return out


def idle_sounding(lm, audio: np.ndarray, end: int, seed: int) -> float:
    """Share of frames after the first 3 s up to frame ``end`` (the end of the recording's music)
    in which the gate of a fresh stream on ``audio`` (n,) is not fully dancing."""
    from models.features.spectral import extract_features

    w = new_stream(lm, seed).listen(extract_features(audio, lm.features))
    return float((w[90:end] > 0).mean()) if end > 90 else 0.0


def stretches(lm, audio: np.ndarray, talk: np.ndarray, end: int, seed: int) -> dict:
    """``--parts stretches``: a fresh stream on ``audio`` + ``talk`` (n,) each, up to frame ``end``,
    the performer never stopping once it dances: the runs of frames its detector and the voice-over
    rule hear as no music (break frames heard), after the first 3 s. Returns ``longest_s``,
    ``at_s`` (its start), ``music_dbfs`` / ``voice_dbfs`` (the levels over it) and ``runs`` (as
    long as :data:`STRETCH_MIN` frames or more)."""
    from models.features.spectral import extract_features

    feats = extract_features((audio + talk).astype(np.float32), lm.features)
    ig = new_stream(lm, seed)._idle
    heard = np.ones(min(end, len(feats)), bool)
    for t in range(len(heard)):
        was = ig.music
        ig.step(np.asarray(feats[t], np.float32))
        if was and not ig.music:  # the stop undone: it dances on, its statistics as they run
            ig.music, ig.run, ig.w_idle = True, 0.0, 0.0
        heard[t] = not was or ig.present or ig.break_frames > 0
    d = np.diff(np.r_[0, (~heard[90:]).astype(int), 0])
    a, b = np.flatnonzero(d > 0) + 90, np.flatnonzero(d < 0) + 90
    if not len(a):
        return {"longest_s": 0.0, "at_s": None, "music_dbfs": None, "voice_dbfs": None, "runs": 0}
    k = int(np.argmax(b - a))
    seg = slice(int(a[k]) * HOP, int(b[k]) * HOP)
    return {"longest_s": (b[k] - a[k]) / 30, "at_s": a[k] / 30, "music_dbfs": rms_dbfs(audio[seg]),
            "voice_dbfs": rms_dbfs(talk[seg]), "runs": int(((b - a) >= STRETCH_MIN).sum())}


def talkover_rows(lm, shared: list, talk: np.ndarray, seed: int) -> list[dict]:
    """``--parts talkover``: for each (name, audio) of ``shared`` (20 s of a recording) and each of
    :data:`MIX_DB`, the readers ``talk`` over it (a different stretch of them per recording) going on
    alone :data:`TALKOVER_S` s after the music stops: ``settle_s``, seconds from the music's end to
    fully idle (None: never)."""
    from models.features.spectral import extract_features

    rows = []
    for k, (name, a) in enumerate(shared):
        a = a[: len(a) // HOP * HOP]
        t = np.roll(talk, -k * 7 * SR)[: len(a) + int(TALKOVER_S * SR)]
        for db in MIX_DB:
            gain = 10 ** ((rms_dbfs(a) - rms_dbfs(talk) + db) / 20)
            x = (np.concatenate([a, np.zeros(len(t) - len(a), np.float32)]) + gain * t).astype(np.float32)
            w = new_stream(lm, seed).listen(extract_features(x[: len(x) // HOP * HOP], lm.features))
            idle = np.flatnonzero(w[len(a) // HOP:] >= 1.0)
            rows.append({"recording": name, "speech_db": db, "settle_s": (idle[0] + 1) / 30 if len(idle) else None})
    return rows


def longest_not_idle_s(w: np.ndarray) -> float:
    """The longest run (s) of frames not fully idle in idle weights ``w`` (T,): from a false start's first frame
    to the performer fully idle again (0: fully idle throughout)."""
    d = np.diff(np.r_[0, (np.asarray(w) < 1.0).astype(int), 0])
    return float((np.flatnonzero(d < 0) - np.flatnonzero(d > 0)).max()) / 30 if (d > 0).any() else 0.0


def leadin_rows(lm, speech: list, seed: int, draws: int = LEADIN_DRAWS, song: np.ndarray | None = None) -> list[dict]:
    """``--parts leadin``: for each of ``speech`` ((name, audio) pairs), :data:`LEADIN_HOSTS` espeak-ng hosts and
    the gaps' noises but silence, 30 s each (speech at -20 dBFS) from a fresh stream's start: ``case``,
    ``not_idle`` (share of frames not fully idle) and ``longest_s`` (:func:`longest_not_idle_s`) at the study's
    draw (:data:`LEADIN_SEED`); ``draws``: (not_idle, longest_s) of the same case drawn at seeds 0 to ``draws`` - 1
    (the noises and hosts; the readers are the same at every draw: none); with ``song`` (n,), ``back_s``: the
    case's first :data:`LEADIN_THEN_S` s then ``song``, seconds from the song's start to fully dancing (None:
    never)."""
    from models.features.spectral import extract_features

    listen = lambda x: new_stream(lm, seed).listen(extract_features(x, lm.features))  # noqa: E731
    other: dict[str, list[tuple[float, float]]] = {}
    for k in range(draws):
        for name, x in leadin_audio([], k):
            v = listen(x)
            other.setdefault(name, []).append((float((v < 1.0).mean()), longest_not_idle_s(v)))
    rows = []
    for name, x in leadin_audio(speech):
        w = listen(x)
        row = {"case": name, "not_idle": float((w < 1.0).mean()), "longest_s": longest_not_idle_s(w),
               "draws": other.get(name, [])}
        if song is not None:
            g1 = int(LEADIN_THEN_S * 30)
            v = listen(np.concatenate([x[: g1 * HOP], song]).astype(np.float32))
            row["back_s"] = (int(np.argmax(v[g1:] <= 0.0)) + 1) / 30 if (v[g1:] <= 0.0).any() else None
        rows.append(row)
    return rows


def leadin_audio(speech: list, seed: int = LEADIN_SEED) -> list[tuple[str, np.ndarray]]:
    """The cases of ``--parts leadin``: (name, audio (n,) float32 at :data:`SR`, whole hops) for each of
    ``speech`` ((name, audio) pairs) and the espeak-ng hosts at -20 dBFS, and the gaps' noises but silence,
    drawn with ``seed``."""
    from models.training import music_gate as mg

    rng = np.random.default_rng(seed)
    pool = [mg.utterance(rng) for _ in range(24)] if mg.espeak_available() else []
    cases = [(n.removesuffix(".ogg"), x) for n, x in speech]
    cases += [(lab, gap_audio(kind, 30.0, lvl, rng, pool)) for lab, kind, lvl in GAPS
              if kind != "silence" and (pool or kind != "crowd")]
    cases += [(f"espeak-ng host {i}", mg.speech(30.0, rng, pool)) for i in range(LEADIN_HOSTS if pool else 0)]
    out = []
    for name, x in cases:
        x = x[: len(x) // HOP * HOP]
        if not name.startswith(tuple(k for k, _, _ in GAPS)):
            x = x * 10 ** ((-20.0 - rms_dbfs(x)) / 20)  # a voice at -20 dBFS
        out.append((name, x.astype(np.float32)))
    return out


def excerpt(data: Path, name: str, seconds: float) -> np.ndarray:
    from models.data.dwm import load_dance
    from models.features.audio_io import load_audio

    song = load_audio(load_dance(data / name).audio_path, SR)[0]
    start = len(song) // 3  # from the middle of the song: full music, no intro
    x = song[start: start + int(seconds * SR)]
    return x[: len(x) // HOP * HOP]


def run_gap(lm, a: np.ndarray, gap: np.ndarray, b: np.ndarray, seed: int) -> dict:
    """Song ``a``, ``gap``, song ``b`` through a fresh stream: the gap's settle, held, back, fade steps."""
    from models.features.spectral import extract_features

    gap = gap[: len(gap) // HOP * HOP]
    audio = np.concatenate([a, gap, b]).astype(np.float32)
    feats = extract_features(audio, lm.features)
    stream = new_stream(lm, seed)
    poses = np.empty((len(feats), lm.model.config.pose_dim), np.float32)
    w = np.empty(len(feats))
    for t in range(len(feats)):
        poses[t] = stream.push(feats[t: t + 1])[0]
        w[t] = stream.idle_weight
    g0, g1 = len(a) // HOP, (len(a) + len(gap)) // HOP
    steps = bone_steps_deg(poses)
    idle_at = g0 + int(np.argmax(w[g0:g1] >= 1.0)) if (w[g0:g1] >= 1.0).any() else None
    back_at = g1 + int(np.argmax(w[g1:] <= 0.0)) if idle_at is not None and (w[g1:] <= 0.0).any() else None
    still = np.flatnonzero((w[:-1] >= 1.0) & (w[1:] >= 1.0))  # steps between two fully idle frames
    still = still[(still >= g0) & (still < g1)]
    fades = np.r_[g0:(idle_at or g1), g1:(back_at or len(w))]
    fades = fades[(fades > 0) & (fades < len(steps) + 1)] - 1
    dancing = np.r_[60:g0, g1 + 60:len(w) - 1] if back_at else np.r_[60:g0]
    return {"settle_s": None if idle_at is None else (idle_at - g0 + 1) / 30.0,
            "held": None if idle_at is None else float((w[idle_at:g1] >= 1.0).mean()),
            "back_s": None if back_at is None else (back_at - g1 + 1) / 30.0,
            "max_step_deg": float(steps[fades].max()) if len(fades) else 0.0,
            "idle_step_deg": float(steps[still].max()) if len(still) else None,
            "dance_step_p99_deg": float(np.percentile(steps[dancing[dancing < len(steps)]], 99)),
            "idle_w": w.tolist(), "gap_frames": [g0, g1]}


def espeak_rows(lm, data: Path, seed: int) -> tuple[list[dict], list[dict]]:
    """``--parts espeak``: (mix rows: ``song``, idle with a host over it at each of :data:`MIX_DB`;
    host rows: ``song``, ``settle_s``, ``held``, ``back_s``) on :data:`ESPEAK_SONGS` training songs."""
    from models.training import music_gate as mg

    rng = np.random.default_rng(ESPEAK_SEED)
    names = mg.training_songs(data)
    pick = [names[i] for i in rng.choice(len(names), ESPEAK_SONGS, replace=False)]
    songs = mg.song_audio(data, pick)
    pool = [mg.utterance(rng) for _ in range(30)]
    cut = lambda x: x[: len(x) // HOP * HOP]  # noqa: E731
    mixes, hosts = [], []
    for name, song in zip(pick, songs):
        a = cut(song[len(song) // 3: len(song) // 3 + 60 * SR])
        talk = mg.speech(70.0, rng, pool)
        row = {"song": name}
        for db in MIX_DB:
            row[f"host {db:g} dB"] = idle_sounding(lm, with_speech(a, talk, db, len(a) // HOP), len(a) // HOP, seed)
        a0 = cut(song[: 30 * SR])  # the song's start under the host: its first 30 s
        for db in MIX_DB:
            row[f"from its start {db:g} dB"] = idle_sounding(lm, with_speech(a0, talk, db, len(a0) // HOP), len(a0) // HOP, seed)
        mixes.append(row)
    for i, (name, song) in enumerate(zip(pick, songs)):
        a = cut(song[len(song) // 3: len(song) // 3 + 20 * SR])
        b = songs[(i + 1) % len(songs)]
        b = cut(b[len(b) // 2: len(b) // 2 + 20 * SR])
        for _ in range(2):
            t = mg.speech(10.0, rng, pool)
            r = run_gap(lm, a, t * 10 ** ((rms_dbfs(a) - rms_dbfs(t)) / 20), b, seed)
            hosts.append({"song": name, **{k: r[k] for k in ("settle_s", "held", "back_s")}})
    return mixes, hosts


def print_trace(lm, args, recordings: list, speech: list, songs: list) -> int:
    """``--trace``: the gate's state frame by frame (:func:`trace`) on a shared recording with the
    readers over it, on a reader after one, or on a gap between songs (``gap:LABEL``, as the gaps
    part draws it at ``--gap-s`` and ``--seed``); 2 on a name that matches nothing."""
    from models.evaluation.listening import music_end
    from models.features.spectral import extract_features

    if args.trace.startswith("gap:"):
        from models.training import music_gate as mg

        rng = np.random.default_rng(1000 + args.seed)  # drawn as main() draws them
        pool = [mg.utterance(rng) for _ in range(24)] if mg.espeak_available() else []
        cases = [(lab, gap_audio(kind, args.gap_s, lvl, rng, pool)) for lab, kind, lvl in GAPS if pool or kind != "crowd"]
        at = [i for i, (lab, _) in enumerate(cases) if lab == args.trace[4:]]
        if not at:
            print(f"idle_gate: --trace {args.trace!r}: no gap {args.trace[4:]!r}; known: {', '.join(g for g, _ in cases)}",
                  file=sys.stderr)
            return 2
        i = at[0]
        a, gap, b = songs[i % len(songs)], cases[i][1], songs[(i + 1) % len(songs)]
        gap = gap[: len(gap) // HOP * HOP]
        feats = extract_features(np.concatenate([a, gap, b]).astype(np.float32), lm.features)
        g0, g1 = len(a) // HOP, (len(a) + len(gap)) // HOP
        print(f"{cases[i][0]} ({args.gap_s:g} s, seed {args.seed}) between songs: the gap's first 3 s from {g0 / 30:.2f} s, "
              f"the music's return at {g1 / 30:.2f} s")
        print("\n".join(trace(lm, feats, [(g0 - 3, g0 + 90), (g1 - 3, g1 + 45)])))
        return 0
    if args.trace.startswith("espeak:"):
        return print_espeak_trace(lm, args)
    if args.trace.startswith("leadin:"):
        return print_leadin_trace(lm, args, speech)
    name, _, what = args.trace.partition("@")
    shared = [(n, a) for n, a in recordings if n in {f.name for f in args.music.glob("*.ogg")}]
    rec = [(i, n, a) for i, (n, a) in enumerate(shared) if n.startswith(name)]
    reader = [(n, x) for n, x in speech if n.removeprefix("librispeech_").startswith(what) or n.startswith(what)]
    if not rec or not what:
        print(f"idle_gate: --trace {args.trace!r}: no shared recording starts with {name!r} (RECORDING@DB or RECORDING@READER)",
              file=sys.stderr)
        return 2
    i, rname, whole = rec[0]
    audio = whole[: len(whole) // HOP * HOP]
    if reader:  # cut as --parts readers cuts (from the whole recording)
        cut = lambda x: x[int(len(x) * args.reader_at): int(len(x) * args.reader_at) + int(args.song_s * SR)]  # noqa: E731
        a, b = cut(whole), cut(shared[(i + 1) % len(shared)][1])
        a, b = a[: len(a) // HOP * HOP], b[: len(b) // HOP * HOP]
        talk = reader[0][1] * 10 ** ((rms_dbfs(a) - rms_dbfs(reader[0][1])) / 20)
        talk = talk[: len(talk) // HOP * HOP]
        feats = extract_features(np.concatenate([a, talk, b]).astype(np.float32), lm.features)
        g0 = len(a) // HOP
        g1 = g0 + len(talk) // HOP
        print(f"{reader[0][0]} after {rname} (the gap starts at {g0 / 30:.2f} s, the next recording at {g1 / 30:.2f} s)")
        lines = trace(lm, feats, [(g0 - 3, g0 + 75), (g1 - 3, g1 + 45)])
    else:
        try:
            db = float(what)
        except ValueError:
            print(f"idle_gate: --trace {args.trace!r}: {what!r} is neither a level (dB) nor a reader", file=sys.stderr)
            return 2
        sound, _ = music_end(lm, extract_features(audio, lm.features), Path(rname).stem)
        talk = np.concatenate([x for _, x in speech])
        feats = extract_features(with_speech(audio, talk, db, sound, args.voice_from), lm.features)
        print(f"{rname} with the readers over it at {db:g} dB from {args.voice_from:g} s: every stop after 3 s")
        lines = trace(lm, feats, [(0, 0)])
    print("\n".join(lines))
    return 0


def print_leadin_trace(lm, args, speech: list) -> int:
    """``--trace leadin:CASE``: the gate's state frame by frame through a case of ``--parts leadin``
    (drawn as :func:`leadin_rows` draws them, e.g. 'leadin:espeak-ng host 1'; 'leadin:crowd -30/3': at the other
    draw of seed 3), every frame it is not
    fully idle or the false start's doubt holds the voice-over start back, from 1 s before; 2 on a case
    that is not there."""
    from models.features.spectral import extract_features

    name, _, draw = args.trace.removeprefix("leadin:").partition("/")
    cases = dict(leadin_audio(speech, int(draw) if draw.isdigit() else LEADIN_SEED))
    if name not in cases:
        print(f"idle_gate: --trace {args.trace!r}: no case {name!r}; known: {', '.join(cases)}", file=sys.stderr)
        return 2
    feats = extract_features(cases[name], lm.features)
    ig = new_stream(lm, args.seed)._idle
    w, held_back = np.empty(len(feats)), np.zeros(len(feats), bool)
    for t in range(len(feats)):
        k = ig.presence.false_start.frames if ig.presence is not None else 0
        w[t] = ig.step(np.asarray(feats[t], np.float32))
        held_back[t] = ig.presence is not None and ig.presence.false_start.frames > k
    moving = np.flatnonzero((w < 1.0) | held_back)
    windows = []
    for t in moving:  # runs of frames not fully idle or held back by the doubt (D), each from 1 s before
        if windows and t <= windows[-1][1] + 30:
            windows[-1] = (windows[-1][0], int(t))
        else:
            windows.append((max(0, int(t) - 30), int(t)))
    print(f"{name} from the stream's start ({len(feats) / 30:.0f} s): not fully idle {float((w < 1.0).mean()):.3f} of it, "
          f"the voice-over start held back by a false start's doubt on {int(held_back.sum())} frames")
    print("\n".join(trace(lm, feats, windows) if windows else ["(fully idle throughout)"]))
    return 0


def espeak_host(data: Path, song_k: str) -> tuple[np.ndarray | None, int, int, list[str]]:
    """Host K (0 or 1) after training song SONG of ``--parts espeak`` (``song_k``: 'SONG/K', drawn as
    :func:`espeak_rows` draws them): (audio (n,) float32 at :data:`SR`: the song's 20 s, the host at its
    level, the next song's 20 s; the host's first frame; the next song's first frame; every 'SONG/K'
    there is). The audio is None where ``song_k`` is none of them."""
    from models.training import music_gate as mg

    rng = np.random.default_rng(ESPEAK_SEED)
    names = mg.training_songs(data)
    pick = [names[i] for i in rng.choice(len(names), ESPEAK_SONGS, replace=False)]
    known = [f"{n}/{k}" for n in pick for k in (0, 1)]
    if song_k not in known:
        return None, 0, 0, known
    songs = mg.song_audio(data, pick)
    pool = [mg.utterance(rng) for _ in range(30)]
    for _ in pick:
        mg.speech(70.0, rng, pool)  # the mixes' voices, drawn first
    cut = lambda x: x[: len(x) // HOP * HOP]  # noqa: E731
    for i, (name, song) in enumerate(zip(pick, songs)):
        a, b = cut(song[len(song) // 3: len(song) // 3 + 20 * SR]), songs[(i + 1) % len(songs)]
        b = cut(b[len(b) // 2: len(b) // 2 + 20 * SR])
        for k in range(2):
            t = mg.speech(10.0, rng, pool)
            if f"{name}/{k}" == song_k:
                t = cut(t * 10 ** ((rms_dbfs(a) - rms_dbfs(t)) / 20))
                return np.concatenate([a, t, b]).astype(np.float32), len(a) // HOP, (len(a) + len(t)) // HOP, known
    return None, 0, 0, known


def print_espeak_trace(lm, args) -> int:
    """``--trace espeak:SONG/K``: the gate's state frame by frame through host K (0 or 1) after the
    training song SONG of ``--parts espeak`` (:func:`espeak_host`): the gap's first 2.5 s and the next
    song's first 1.5 s; 2 on a song or host that is not there."""
    from models.features.spectral import extract_features

    song_k = args.trace.removeprefix("espeak:")
    audio, g0, g1, known = espeak_host(args.data, song_k)
    if audio is None:
        print(f"idle_gate: --trace {args.trace!r}: no host {song_k!r}; known: {', '.join(known)}", file=sys.stderr)
        return 2
    name, k = song_k.rsplit("/", 1)
    print(f"espeak-ng host {k} after {name} (the gap starts at {g0 / 30:.2f} s, the next song at {g1 / 30:.2f} s)")
    print("\n".join(trace(lm, extract_features(audio, lm.features), [(g0 - 3, g0 + 75), (g1 - 3, g1 + 45)])))
    return 0


def settle_target(gap: str) -> float:
    """Most seconds to fully idle on gap ``gap`` (its label): :data:`SETTLE_TARGET_S`."""
    return SETTLE_TARGET_S.get(gap.split()[0], SETTLE_TARGET_OTHER_S)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", default=None, help="a dance_vq checkpoint (default: the packaged one)")
    p.add_argument("--data", required=True, type=Path, help="the DWM dataset directory (validation songs)")
    p.add_argument("--music", type=Path, default=Path("../shared/data/music"), help="recordings to stay danced on")
    p.add_argument("--speech", type=Path, default=Path("../shared/data/speech"), help="read speech to idle on")
    p.add_argument("--song-s", type=float, default=20.0, help="seconds of each song around a gap (default 20)")
    p.add_argument("--gap-s", type=float, default=10.0, help="seconds of each noise gap (default 10)")
    p.add_argument("--seed", type=int, default=7, help="noise and dance seed (default 7)")
    p.add_argument("--plot", type=Path, help="write a PNG of the idle weight over the between-songs programmes")
    p.add_argument("--json", type=Path, help="write the results as JSON")
    p.add_argument("--parts", default="recordings,mixes,gaps",
                   help="comma-separated parts to run: recordings, mixes (voices and breaks), gaps, readers (after each "
                        "recording), espeak (espeak-ng hosts over and after training songs), stretches (the voices over the music with "
                        "the stop undone: how long the gate hears no music), leadin (no music from the stream's start), talkover "
                        "(the readers over a recording going on alone after it) "
                        "(default recordings,mixes,gaps)")
    p.add_argument("--leadin-draws", type=int, default=LEADIN_DRAWS, metavar="N",
                   help=f"--parts leadin also draws its noises and hosts at seeds 0 to N-1 (default {LEADIN_DRAWS}; 0: "
                        f"its one draw only) and shows the spread")
    p.add_argument("--voice-from", type=float, default=0.0, metavar="S",
                   help="--parts mixes: the readers come in S seconds into each recording, after the performer has "
                        "danced (a rapper after an instrumental intro; default 0: over all of it); --trace RECORDING@DB too")
    p.add_argument("--reader-at", type=float, default=1 / 3,
                   help="--parts readers: where the 20 s of each recording start, a share of its length (default 1/3)")
    p.add_argument("--floor-db", type=float, help="the voice-over rule's FLOOR_DB (models/networks/music_gate.py; "
                   "inf: the voice network alone, 0: the rule off)")
    p.add_argument("--voice-margin", type=float, help="the voice-over rule's VOICE_MARGIN (inf: the floor alone)")
    p.add_argument("--pause-steady", type=float,
                   help="the pause rule's PAUSE_STEADY (voice_pauses.PAUSE_STEADY; inf: the pause rule off)")
    p.add_argument("--start-evidence", type=float,
                   help="the voice-over start's START_EVIDENCE, frames (voice_start.START_EVIDENCE; inf: an idle performer "
                        "starts on its detector alone)")
    p.add_argument("--start-decay", type=float,
                   help="the voice-over start's START_DECAY (voice_start.START_DECAY: frames a frame without evidence takes off)")
    p.add_argument("--voice-hold", type=int, help="frames the voice-over context holds a stop (voice_context.VOICE_HOLD)")
    p.add_argument("--gone-floor-db", type=float, help="the voice-over context's release: voice_context.GONE_FLOOR_DB (inf: never released)")
    p.add_argument("--gone-steady", type=float, help="the voice-over context's release: voice_context.GONE_STEADY (dimensionless)")
    p.add_argument("--gone-voice", type=float, help="the voice-over context's release where the voice network is sure of no "
                   "music: voice_context.GONE_VOICE (its logit at or below minus it, the floor broken; inf: off)")
    p.add_argument("--voice-no", type=float, help="the veto's threshold: veto.VOICE_NO (the voice network's logit at or below minus it)")
    p.add_argument("--veto-top", type=float, help="the veto's reach while a stop count runs: veto.VETO_TOP "
                   "(stop logit; 0 with --voice-no-run 4: as when none runs)")
    p.add_argument("--voice-no-run", type=float, help="the veto's threshold while a stop count runs: veto.VOICE_NO_RUN")
    p.add_argument("--agree-stop", type=float, help="the three networks' agreement on an idle frame: the stop network's "
                   "threshold, agreement.AGREE_STOP (inf: the agreement off)")
    p.add_argument("--agree-voice", type=float, help="the three networks' agreement: the voice network's threshold, "
                   "agreement.AGREE_VOICE")
    p.add_argument("--confirm-frames", type=int, help="frames the stop network must hear as music for a dance not to be "
                   "a false start (false_start.CONFIRM_FRAMES)")
    p.add_argument("--resume-frames", type=int, help="frames after a false start's stop the voice-over start may still "
                   "start the dance (false_start.RESUME_FRAMES)")
    p.add_argument("--confirm-voice", type=float, help="after the stream's first dance, a start of the detector's waits "
                   "until the voice network's logit is above this (return_confirm.CONFIRM_VOICE; -inf: as --off return-confirm)")
    p.add_argument("--unsure-top", type=float, help="a dancing frame whose stop logit lies at or below this, the voice-over "
                   "rule's cues holding, is a voice heard over the music for the context (unsure_voice.UNSURE_TOP; -inf: as "
                   "--off unsure-voice)")
    p.add_argument("--song-margin", type=float, help="a song's start is guarded while the voice network's logit lies above "
                   "minus this (idle_gate.SONG_MARGIN; 2: as before the false start's doubt)")
    p.add_argument("--song-margin-voiced", type=float, help="the same for a song's start the voice-over start made "
                   "(idle_gate.SONG_MARGIN_VOICED; --off voiced-song: as any other)")
    p.add_argument("--song-dance", type=int, help="frames a song's start is danced (idle_gate.SONG_DANCE; 0: as --off song-start)")
    p.add_argument("--off", default="", help="comma-separated parts of the gate to switch off: break-count (a break danced "
                   "through voids the whole stop count), fresh (the statistics keep their time constant after a silence), resume (the "
                   "voice-over start's count starts from 0 at a stop), song-start (the detector may stop a song's start at once), quiet-return (a break's end "
                   "voids its count even on a quiet frame heard as no music), veto (an unsure stop network is not "
                   "overruled by a sure voice network), context (a voice heard over the dance before does not hold its "
                   "stop for voice_context.VOICE_HOLD frames), agree (an idle performer does not start where the detector, the stop "
                   "and the voice network agree on music, the detector under music_gate.MARGIN_START), false-start (the "
                   "voice-over start starts the dance again after a dance the stop network never heard as music), "
                   "voiced-song (a song's start the voice-over start made is guarded as any other, at idle_gate.SONG_MARGIN), "
                   "lone-voice (the pause rule keeps a frame whatever the voice network hears where no voice was heard over the "
                   "dance: lone_voice.py), return-confirm (after the stream's first dance the detector starts the dance "
                   "without the voice network), unsure-voice (the voice-over context counts only the frames its rules kept, "
                   "not a voice heard where the stop network wavers: unsure_voice.py), sharp-return (an idle performer does not "
                   "take the stop or the voice network's word alone right after a silence or on a rise over the gap's level: "
                   "sharp_return.py), host (the voice-over and pause rules keep a host's words after a song that stopped at "
                   "once: song_end.py)")
    p.add_argument("--trace", help="print the gate's state frame by frame instead of the tables: RECORDING@DB (a shared "
                   "recording, a prefix of its name, with the readers over it at DB dB: every stop after 3 s) or "
                   "RECORDING@READER (a reader, a prefix of its name, after 20 s of the recording from --reader-at: "
                   "the gap's first 2.5 s and the next recording's first 1.5 s) or gap:LABEL (a gap between songs as the gaps part "
                   "draws it at --gap-s and --seed, e.g. 'gap:crowd -30': its first 3 s and the music's return) or "
                   "espeak:SONG/K (espeak-ng host K, 0 or 1, after training song SONG of --parts espeak) or leadin:CASE "
                   "(a case of --parts leadin from the stream's start, e.g. 'leadin:espeak-ng host 1': every frame not fully idle; "
                   "'leadin:crowd -30/3': at its other draw of seed 3)")
    args = p.parse_args(argv)
    parts = set(args.parts.split(","))
    off = {o for o in args.off.split(",") if o}
    if off - set(SWITCHES):
        p.error(f"--off: unknown part(s) {sorted(off - set(SWITCHES))}; known: {', '.join(SWITCHES)}")
    OFF.update(off)
    known = {"recordings", "mixes", "gaps", "readers", "espeak", "stretches", "leadin", "talkover"}
    if parts - known:
        p.error(f"--parts: unknown part(s) {sorted(parts - known)}")

    from models.errors import PerformerError
    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model
    from models.networks import music_gate as gate
    from models.training import music_gate as mg

    from models.networks import (agreement, false_start, return_confirm, unsure_voice, veto, voice_context, voice_pauses,
                                 voice_start)

    for arg, const in (("floor_db", "FLOOR_DB"), ("voice_margin", "VOICE_MARGIN"), ("pause_steady", "PAUSE_STEADY"),
                       ("start_evidence", "START_EVIDENCE"), ("start_decay", "START_DECAY"), ("voice_hold", "VOICE_HOLD"),
                       ("gone_floor_db", "GONE_FLOOR_DB"), ("gone_steady", "GONE_STEADY"), ("gone_voice", "GONE_VOICE"), ("voice_no", "VOICE_NO"), ("veto_top", "VETO_TOP"),
                       ("voice_no_run", "VOICE_NO_RUN"), ("agree_stop", "AGREE_STOP"), ("agree_voice", "AGREE_VOICE"),
                       ("confirm_frames", "CONFIRM_FRAMES"), ("resume_frames", "RESUME_FRAMES"),
                       ("confirm_voice", "CONFIRM_VOICE"), ("unsure_top", "UNSURE_TOP")):
        if getattr(args, arg) is not None:  # a constant set on the module that defines it (models/networks/)
            where = (voice_context, voice_pauses, voice_start, veto, agreement, false_start, return_confirm, unsure_voice, gate)
            setattr(next(m for m in where if hasattr(m, const)), const, getattr(args, arg))
    from models.networks import idle_gate

    if args.song_dance is not None:
        idle_gate.SONG_DANCE = args.song_dance
    if args.song_margin is not None:
        idle_gate.SONG_MARGIN = args.song_margin
    if args.song_margin_voiced is not None:
        idle_gate.SONG_MARGIN_VOICED = args.song_margin_voiced
    try:
        lm = load_model(args.checkpoint)
        if not getattr(lm.model, "takes_style", False):
            raise PerformerError(f"{lm.path} is a {lm.name!r} model; the idle gate belongs to dance_vq models")
        recordings = [(f.name, load_audio(f, SR)[0]) for f in sorted(args.music.glob("*.ogg"))]
        from models.data.dwm import load_dance
        recordings += [(n, load_audio(load_dance(args.data / n).audio_path, SR)[0]) for n in VAL_DANCES]
        speech = [(f.name, load_audio(f, SR)[0]) for f in sorted(args.speech.glob("*.ogg"))]
        songs = [excerpt(args.data, n, args.song_s) for n in VAL_DANCES]
    except (PerformerError, OSError) as e:
        print(f"idle_gate: {e}", file=sys.stderr)
        return 2
    if args.trace:
        return print_trace(lm, args, recordings, speech, songs)
    fitted = bool(lm.model.presence.abs().sum() > 0)
    print(f"{lm.path}: detector {'presence network (models/networks/music_gate.py)' if fitted else 'logistic (older checkpoint)'}")

    import time

    rec_rows, cost = [], []
    for name, audio in (recordings if "recordings" in parts else []):
        feats = extract_features(audio, lm.features)
        stream = new_stream(lm, args.seed)
        w = np.empty(len(feats))
        for t in range(len(feats)):  # one frame at a time, as the engine pushes them
            t0 = time.perf_counter()
            w[t] = stream.listen(feats[t: t + 1])[0]
            cost.append(time.perf_counter() - t0)
        idle = w[90:] > 0
        runs = np.diff(np.r_[0, idle.astype(int), 0])
        longest = int((np.flatnonzero(runs < 0) - np.flatnonzero(runs > 0)).max()) if idle.any() else 0
        sound, end = music_end(lm, feats, Path(name).stem)  # the end of its music: applause after it is not music
        rec_rows.append({"recording": name, "s": len(audio) / SR, "idle": float(idle.mean()), "longest_idle_s": longest / 30,
                         "silent_tail_s": (len(feats) - sound) / 30, "after_music_s": (sound - end) / 30,
                         "idle_sounding": float((w[90:end] > 0).mean()) if end > 90 else 0.0})
    cost_us = np.array(cost) * 1e6 if cost else np.zeros(1)
    if rec_rows:  # each table only for a part that ran (--parts)
        print(f"the gate's cost per frame (DanceStream.listen of one frame): median {np.median(cost_us):.1f} us, "
              f"p99 {np.percentile(cost_us, 99):.1f} us over {len(cost_us)} frames")
        print("\n| recording | s | idle after 3 s, to the file's end | longest idle (s) | silent end (s) | applause before it (s) "
              "| idle to the end of the music ≤ 0.02 |")
        print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for r in rec_rows:
        print(f"| {r['recording']} | {r['s']:.0f} | {r['idle']:.3f} | {r['longest_idle_s']:.1f} | {r['silent_tail_s']:.1f} | "
              f"{r['after_music_s']:.1f} | {r['idle_sounding']:.3f} |")

    mix_rows = []
    talk = np.concatenate([s for _, s in speech]) if speech else None
    for name, audio in (recordings if "mixes" in parts and talk is not None else []):
        if name not in {f.name for f in args.music.glob("*.ogg")}:
            continue  # the shared recordings only
        audio = audio[: len(audio) // HOP * HOP]
        sound, end = music_end(lm, extract_features(audio, lm.features), Path(name).stem)
        row = {"recording": name, "alone": idle_sounding(lm, audio, end, args.seed)}
        for db in MIX_DB:
            row[f"speech {db:g} dB"] = idle_sounding(lm, with_speech(audio, talk, db, sound, args.voice_from), end, args.seed)
        for sec in BREAKS_S:
            row[f"breaks {sec:g} s"] = idle_sounding(lm, with_breaks(audio, sec), end, args.seed)
        mix_rows.append(row)
    if mix_rows:
        cols = [k for k in mix_rows[0] if k != "recording"]
        print(f"\n| recording (idle to the end of the music ≤ 0.02) | {' | '.join(cols)} |")
        print("| --- |" + " ---: |" * len(cols))
        for r in mix_rows:
            print(f"| {r['recording']} | " + " | ".join(f"{r[c]:.3f}" for c in cols) + " |")
        print(f"| worst | " + " | ".join(f"{max(r[c] for r in mix_rows):.3f}" for c in cols) + " |")

    stretch_rows = []
    for name, audio in (recordings if "stretches" in parts and talk is not None else []):
        if name not in {f.name for f in args.music.glob("*.ogg")}:
            continue  # the shared recordings only
        audio = audio[: len(audio) // HOP * HOP]
        sound, end = music_end(lm, extract_features(audio, lm.features), Path(name).stem)
        for db in MIX_DB:
            voice = with_speech(audio, talk, db, sound) - audio
            stretch_rows.append({"recording": name, "speech_db": db, **stretches(lm, audio, voice, end, args.seed)})
    if stretch_rows:
        print(f"\n| recording, the readers over it, the stop undone | speech dB | longest run heard as no music (s) | from (s) | "
              f"music / voice over it (dBFS) | runs of {STRETCH_MIN} frames or more |")
        print("| --- | ---: | ---: | ---: | ---: | ---: |")
        for r in stretch_rows:
            lv = "-" if r["at_s"] is None else f"{r['music_dbfs']:.1f} / {r['voice_dbfs']:.1f}"
            at = "-" if r["at_s"] is None else f"{r['at_s']:.1f}"
            print(f"| {r['recording']} | {r['speech_db']:g} | {r['longest_s']:.2f} | {at} | {lv} | {r['runs']} |")

    talk_rows = [] if "talkover" not in parts or talk is None else talkover_rows(lm, [
        (n, a[int(len(a) * args.reader_at): int(len(a) * args.reader_at) + int(args.song_s * SR)]) for n, a in recordings
        if n in {f.name for f in args.music.glob("*.ogg")}], talk, args.seed)
    if talk_rows:
        f2 = lambda v: "never" if v is None else f"{v:.2f}"  # noqa: E731
        print("\n| the readers over a recording, going on alone after it: settle (s ≤ 2) | "
              + " | ".join(f"{db:g} dB" for db in MIX_DB) + " |\n| --- |" + " ---: |" * len(MIX_DB))
        for k in range(0, len(talk_rows), len(MIX_DB)):
            print(f"| {talk_rows[k]['recording']} | " + " | ".join(f2(r["settle_s"]) for r in talk_rows[k: k + len(MIX_DB)]) + " |")

    lead_rows = leadin_rows(lm, speech, args.seed, args.leadin_draws, songs[0]) if "leadin" in parts else []
    if lead_rows:
        nd = args.leadin_draws
        print(f"\n| no music from the stream's start, 30 s | not fully idle (0) | longest false start (s) | "
              f"{f'draws 0-{nd - 1}' if nd else 'no other draw'}: not fully idle, median / worst | longest false start, worst (s) | "
              f"{LEADIN_THEN_S:g} s of it, then {VAL_DANCES[0]}: back (s) ≤ 1 |\n| --- | ---: | ---: | ---: | ---: | ---: |")
        for r in lead_rows:
            d = r["draws"]
            spread = f"{np.median([a for a, _ in d]):.3f} / {max(a for a, _ in d):.3f} | {max(b for _, b in d):.2f}" \
                if d else "- | -"
            back = "never" if r.get("back_s", 0.0) is None else f"{r['back_s']:.2f}" if "back_s" in r else "-"
            print(f"| {r['case']} | {r['not_idle']:.3f} | {r['longest_s']:.2f} | {spread} | {back} |")

    reader_rows = []
    shared = [(n, a[int(len(a) * args.reader_at): int(len(a) * args.reader_at) + int(args.song_s * SR)]) for n, a in recordings
              if n in {f.name for f in args.music.glob("*.ogg")}] if "readers" in parts else []
    for i, (name, a) in enumerate(shared):
        a = a[: len(a) // HOP * HOP]
        for sname, talk in speech:
            row = run_gap(lm, a, talk * 10 ** ((rms_dbfs(a) - rms_dbfs(talk)) / 20), shared[(i + 1) % len(shared)][1], args.seed)
            reader_rows.append({"recording": name, "reader": sname, **{k: row[k] for k in ("settle_s", "held", "back_s")}})
    if reader_rows:
        print("\n| reader after (s ≤ 2) | " + " | ".join(n.removesuffix(".ogg") for n, _ in speech) + " | held | back (s) |")
        print("| --- |" + " ---: |" * (len(speech) + 2))
        for k in range(0, len(reader_rows), len(speech)):
            rr = reader_rows[k: k + len(speech)]
            f2 = lambda v: "never" if v is None else f"{v:.2f}"  # noqa: E731
            print(f"| {rr[0]['recording']} | " + " | ".join(f2(r["settle_s"]) for r in rr)
                  + f" | {min((r['held'] or 0.0) for r in rr):.2f} | {max((r['back_s'] or 99.0) for r in rr):.2f} |")

    es_mix, es_hosts = espeak_rows(lm, args.data, args.seed) if "espeak" in parts else ([], [])
    if es_mix:
        cols = [k for k in es_mix[0] if k != "song"]
        print(f"\n| training song, an espeak-ng host over it (idle ≤ 0.02) | {' | '.join(cols)} | host after it: settle (s ≤ 2) | held | back (s) |")
        print("| --- |" + " ---: |" * (len(cols) + 3))
        f2 = lambda v: "never" if v is None else f"{v:.2f}"  # noqa: E731
        for r in es_mix:
            hh = [h for h in es_hosts if h["song"] == r["song"]]
            print(f"| {r['song']} | " + " | ".join(f"{r[c]:.3f}" for c in cols) + " | " + " / ".join(f2(h["settle_s"]) for h in hh)
                  + f" | {min((h['held'] or 0.0) for h in hh):.2f} | {max((h['back_s'] or 99.0) for h in hh):.2f} |")
        print(f"| worst | " + " | ".join(f"{max(r[c] for r in es_mix):.3f}" for c in cols)
              + f" | {max((h['settle_s'] or 99.0) for h in es_hosts):.2f} | {min((h['held'] or 0.0) for h in es_hosts):.2f} | "
              f"{max((h['back_s'] or 99.0) for h in es_hosts):.2f} |")

    rng = np.random.default_rng(1000 + args.seed)
    pool = [mg.utterance(rng) for _ in range(24)] if mg.espeak_available() else []
    cases = [(lab, gap_audio(kind, args.gap_s, lvl, rng, pool)) for lab, kind, lvl in GAPS
             if pool or kind not in ("crowd",)]
    gap_rows = []
    for i, (lab, gap) in enumerate([] if "gaps" not in parts else cases + [(f"speech {n.removesuffix('.ogg')}", s) for n, s in speech]):
        a, b = songs[i % len(songs)], songs[(i + 1) % len(songs)]
        if lab.startswith("speech"):
            gap = gap * 10 ** ((rms_dbfs(a) - rms_dbfs(gap)) / 20)  # at the level of the music
        row = run_gap(lm, a, gap, b, args.seed)
        gap_rows.append({"gap": lab, "dbfs": rms_dbfs(gap) if lab != "silence" else None, **row})
    if gap_rows:
        print("\n| between songs | gap dBFS | settle (s) | ≤ | held | back (s) ≤ 1 | largest step in the fades (deg) | "
              "largest step while idle (deg) | dance p99 (deg) |")
        print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    f = lambda v, d=2: "never" if v is None else f"{v:.{d}f}"  # noqa: E731
    for r in gap_rows:
        print(f"| {r['gap']} | {f(r['dbfs'], 1) if r['dbfs'] is not None else '-'} | {f(r['settle_s'])} | "
              f"{settle_target(r['gap']):g} | {f(r['held'])} | "
              f"{f(r['back_s'])} | {r['max_step_deg']:.1f} | {f(r['idle_step_deg'])} | {r['dance_step_p99_deg']:.1f} |")
    if args.json:
        args.json.write_text(json.dumps({"mixes": mix_rows, "stretches": stretch_rows, "talkover": talk_rows, "leadin": lead_rows, "readers": reader_rows, "espeak": es_mix, "espeak_hosts": es_hosts, "gate_us_median": float(np.median(cost_us)),
                                         "gate_us_p99": float(np.percentile(cost_us, 99)), "recordings": rec_rows, "gaps": [{k: v for k, v in r.items() if k != "idle_w"}
                                                                             for r in gap_rows]}, indent=1))
    if args.plot and not gap_rows:
        print(f"idle_gate.py: --plot {args.plot}: the plot draws the gaps between songs; add gaps to --parts", file=sys.stderr)
    if args.plot and gap_rows:  # the plot draws the gaps between songs
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(len(gap_rows), 1, figsize=(9, 0.9 * len(gap_rows) + 0.6), sharex=True)
        for axis, r in zip(np.atleast_1d(ax), gap_rows):
            w = np.array(r["idle_w"])
            g0, g1 = r["gap_frames"]
            axis.axvspan(g0 / 30, g1 / 30, color="0.88", zorder=0)
            axis.plot(np.arange(len(w)) / 30, w, color="C3")
            axis.set_ylim(-0.1, 1.1)
            axis.set_yticks([0, 1])
            axis.set_ylabel(r["gap"], rotation=0, ha="right", va="center", fontsize=8)
        np.atleast_1d(ax)[-1].set_xlabel("s (grey: the gap between two songs); idle weight, 1 = idle")
        fig.tight_layout()
        fig.savefig(args.plot, dpi=90)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

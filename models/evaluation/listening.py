"""Does the performer listen? Tempo, beat, ramp and presence figures of a dance_vq model (issue 25).

Three sets, all generated offline with the live stream
(:class:`models.networks.dance_stream.DanceStream`, as :func:`models.networks.dance_stream.generate` runs it,
pushed frame by frame so its idle weight is read after every frame), scored on FK
positions of the default skeleton (``(T, 30, 3)`` m at 30 fps). docs/metrics.md has one
paragraph per figure; ``benchmarks/listening.py`` and ``performer evaluate --listening``
run them.

1. **Stretch set**: recordings whose whole-file tempo (``librosa.beat.beat_track``) lies in
   :data:`TEMPO_RANGE`, an excerpt of each time-stretched to :data:`STRETCH_RATES` with pitch
   kept (``librosa.effects.time_stretch``; rate > 1 is faster). Per song and rate: mean joint
   speed, frequency centroid, kinematic beats per minute, dance-scale band amplitude, beat
   hit rate against the music's beats and against the beats shifted by half a beat. The
   music's beats are the whole recording's (:meth:`AudioCache.beats`) moved by the known
   stretch (:func:`stretched_beats`), the same musical beats at every rate.
2. **Ramp**: one song played at a rate that rises linearly from :data:`RAMP_RATES` [0] to [1]
   and back (:func:`vary_rate`, a phase vocoder with a time step per frame); the performer's
   joint speed against the real tempo, both smoothed over :data:`SMOOTH_S`.
3. **Presence**: the idle fraction of music recordings after their first :data:`SETTLE_S`,
   up to the end of their music (the last sound, :func:`sounding_frames`, or where applause
   takes over, :data:`MUSIC_ENDS_S`) and, for information, to the file's end; and a song
   interrupted by read speech at the music's RMS level.

Times are counted in motion frames at :data:`FPS` (30); pose ``t`` ends at audio sample
``(t + 1) * HOP`` of the signal the performer hears.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from models.errors import DataError
from models.evaluation.beats import BEAT_TOLERANCE, beat_hit_rate, kinematic_beats, motion_speed
from models.evaluation.metrics import DANCE_BAND, band_rms, in_place
from models.timebase import FPS, HOP, SAMPLE_RATE

#: Time-stretch rates of the stretch set (1.25: 25 % faster than the recording).
STRETCH_RATES: tuple[float, float, float] = (0.8, 1.0, 1.25)
#: Whole-file tempo range (beats per minute) of the recordings in the stretch set.
TEMPO_RANGE: tuple[float, float] = (80.0, 130.0)
#: Band (Hz) of :func:`frequency_centroid`: dance-scale motion up to the start of the jitter band.
CENTROID_BAND: tuple[float, float] = (0.25, 6.0)
#: Seconds at the start of every performance left out of the scores (the stream starts idle
#: and fades in once it hears music).
SETTLE_S: float = 3.0
#: Sampling seeds of the stretch set and the ramp; each figure is the mean over them. One
#: seed's beat hit rate moves by a few hundredths, its ramp correlation by up to 0.2: over
#: seeds 0-2 and over 3-5 the speed ratio differed by 0.06 and the ramp correlation by 0.13
#: (stop 33's model), so three seeds could pass or fail a target by the draw alone.
SEEDS: tuple[int, ...] = (0, 1, 2, 3, 4, 5)
#: Sampling seeds of the ramp (one song, cheap: about 0.7 s a seed). One seed's correlation
#: spreads from about 0.2 to 0.9 (standard deviation 0.16: its draws decide which movements
#: the 4-s windows hold), so a mean over six seeds is uncertain by 0.07, over 48 by 0.02.
RAMP_SEEDS: tuple[int, ...] = tuple(range(48))
#: Smoothing (s, moving average) of tempo and speed in the ramp.
SMOOTH_S: float = 4.0
#: The ramp's rates: from the first to the second over RAMP_S, and back.
RAMP_RATES: tuple[float, float] = (0.85, 1.2)
RAMP_S: float = 30.0
#: Seconds the ramp holds its first rate before rising (the performer settles into the song).
RAMP_HOLD_S: float = 6.0
#: Largest lag (s) searched between the real tempo and the performer's speed.
MAX_LAG_S: float = 5.0
#: Idle weight above which a frame counts as idle.
IDLE_THRESHOLD: float = 0.5
#: Recordings whose music ends before their last sound (seconds from the file's start): a
#: live recording that goes on with its audience's applause, where the performer is to idle
#: as it does between songs. brahms_hungarian5_usarmystrings (US Army Strings, live): the
#: orchestra's harmonics stop at 39.3 s, broadband applause follows until 43.5 s (its
#: spectrogram: docs/img/brahms_end.png; spectral flatness 0.001-0.006 before, 0.08-0.12 after).
MUSIC_ENDS_S: dict[str, float] = {"brahms_hungarian5_usarmystrings": 39.3}

#: (key, description, comparison, threshold) of every target; ``key`` names a figure of :func:`summary`.
TARGETS: tuple[tuple[str, str, str, float], ...] = (
    ("speed_ratio", "mean joint speed 1.25x / 0.8x", ">=", 1.40),
    ("centroid_ratio", "frequency centroid 1.25x / 0.8x", ">=", 1.30),
    ("amp_min", "band amplitude / 1.0x's, lowest rate", ">=", 0.8),
    ("amp_max", "band amplitude / 1.0x's, highest rate", "<=", 1.25),
    ("hit_min", "beat hit rate, lowest rate", ">=", 0.40),
    ("hit_half_min", "beat hit / half-beat-shifted hit, lowest rate", ">=", 1.5),
    ("ramp_corr", "ramp: speed-tempo correlation at best lag", ">=", 0.7),
    ("ramp_lag_s", "ramp: lag of best correlation (s)", "<=", 2.0),
    ("ramp_follower_corr", "ramp: followed tempo-tempo correlation at best lag", ">=", 0.7),
    ("ramp_follower_lag_s", "ramp: lag of the followed tempo (s)", "<=", 2.0),
    ("ramp_max_step_deg", "ramp: largest bone rotation per frame (deg)", "<=", 50.0),
    ("idle_sounding_max", "music: largest idle fraction of a recording, to the end of its music", "<=", 0.02),
    ("speech_settle_s", "speech: seconds to idle, worst case", "<=", 2.0),
    ("speech_held", "speech: idle fraction held after settling, worst case", ">=", 0.95),
    ("speech_back_s", "speech: seconds to dance again, worst case", "<=", 1.0),
)


# --------------------------------------------------------------------------- motion figures


def mean_speed(pos: np.ndarray, fps: float = FPS) -> float:
    """Mean joint speed, m/s: :func:`models.evaluation.beats.motion_speed` averaged over frames."""
    return float(motion_speed(pos, fps).mean())


def frequency_centroid(pos: np.ndarray, fps: float = FPS, band: tuple[float, float] = CENTROID_BAND) -> float:
    """Power-weighted mean frequency (Hz) of the joint velocities in ``band``.

    ``pos (T, J, 3)`` m is put in place (root's horizontal path removed), differentiated
    (central differences, m/s), its mean removed, Hann-windowed, and its power spectrum
    (rfft along time) summed over joints and axes; the centroid is ``sum f P(f) / sum P(f)``
    over the bins with ``band[0] <= f <= band[1]``. Playing a motion ``r`` times faster
    multiplies it by ``r`` (while its spectrum stays inside the band). 0 for a still motion.
    """
    vel = np.gradient(in_place(pos), axis=0) * fps
    vel = vel - vel.mean(axis=0)
    win = np.hanning(len(vel))[:, None, None]
    power = np.abs(np.fft.rfft(vel * win, axis=0)) ** 2
    power = power.sum(axis=(1, 2))
    freq = np.fft.rfftfreq(len(vel), 1.0 / fps)
    keep = (freq >= band[0]) & (freq <= band[1])
    total = power[keep].sum()
    return float((freq[keep] * power[keep]).sum() / total) if total > 0 else 0.0


def kinematic_bpm(pos: np.ndarray, fps: float = FPS) -> float:
    """Kinematic beats per minute: :func:`models.evaluation.beats.kinematic_beats` (dips of the
    smoothed mean joint speed at least 0.02 m/s deep and 6 frames apart) counted over the
    motion, per minute of it. The depth threshold and the smoothing are fixed, so a complex
    motion played faster does not always count proportionally more dips (docs/metrics.md)."""
    return 60.0 * len(kinematic_beats(pos, fps)) * fps / len(pos)


def dance_amplitude(pos: np.ndarray, fps: float = FPS) -> float:
    """Dance-scale band amplitude, m: :func:`models.evaluation.metrics.band_rms` in
    :data:`models.evaluation.metrics.DANCE_BAND` (0.25-3 Hz), the numerator of ``band_amp``."""
    return band_rms(pos, DANCE_BAND, fps)


def half_shifted(beats: np.ndarray) -> np.ndarray:
    """Control beats (frames): the midpoints between consecutive music beats, rounded."""
    b = np.sort(np.asarray(beats, dtype=np.float64))
    return np.unique(np.rint((b[1:] + b[:-1]) / 2).astype(np.int64))


def beat_hits(pos: np.ndarray, beats: np.ndarray, fps: float = FPS, tolerance: int = BEAT_TOLERANCE) -> tuple[float, float]:
    """(beat hit rate against ``beats``, against :func:`half_shifted` ``beats``): the kinematic
    beats of ``pos`` within ``±tolerance`` frames of a music beat (frames at ``fps``)."""
    kin = kinematic_beats(pos, fps)
    b = np.asarray(beats)
    b = b[b < len(pos)]
    return beat_hit_rate(kin, b, tolerance), beat_hit_rate(kin, half_shifted(b), tolerance)


def bone_steps_deg(poses: np.ndarray) -> np.ndarray:
    """(T - 1,) largest bone rotation (degrees) between consecutive poses (T, P) (root
    position then quaternions x, y, z, w per bone): :func:`models.rig.kinematics.rotation_jumps_deg`."""
    from models.rig.kinematics import rotation_jumps_deg

    p = np.asarray(poses, np.float64)
    return rotation_jumps_deg(p[:, 3:].reshape(len(p), -1, 4)).max(1)


def smooth(x: np.ndarray, seconds: float = SMOOTH_S, fps: float = FPS) -> np.ndarray:
    """Centred moving average of ``x (T,)`` over ``seconds`` (edges: the mean of what exists)."""
    n = max(1, int(round(seconds * fps)))
    k = np.ones(n)
    return np.convolve(x, k, "same") / np.convolve(np.ones_like(x, dtype=np.float64), k, "same")


def lagged_correlation(tempo: np.ndarray, speed: np.ndarray, max_lag: int) -> tuple[float, int, float]:
    """(best Pearson correlation, its lag in frames, correlation at lag 0) of ``speed`` following
    ``tempo`` by 0..``max_lag`` frames (speed[t + lag] against tempo[t]); both (T,)."""
    def corr(a: np.ndarray, b: np.ndarray) -> float:
        if a.std() < 1e-12 or b.std() < 1e-12:
            return 0.0
        return float(np.corrcoef(a, b)[0, 1])

    t = len(tempo)
    if len(speed) != t or t < max_lag + 3:
        raise DataError(f"tempo and speed must have the same length > {max_lag + 2}, got {t} and {len(speed)}",
                        source="ramp")
    cs = [corr(tempo[: t - lag], speed[lag:]) for lag in range(max_lag + 1)]
    best = int(np.argmax(cs))
    return cs[best], best, cs[0]


# --------------------------------------------------------------------------- audio


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(np.asarray(x, np.float64)))))


def recording_tempo(audio: np.ndarray) -> float:
    """Tempo (beats per minute) of a whole recording (n,) at 22050 Hz: ``librosa.beat.beat_track``."""
    import librosa

    tempo, _ = librosa.beat.beat_track(y=np.asarray(audio, np.float32), sr=SAMPLE_RATE, hop_length=HOP)
    return float(np.atleast_1d(tempo)[0])


def heard_beats(audio: np.ndarray) -> np.ndarray:
    """Music beat frames of a signal the performer hears from its sample 0 (pose ``t`` ends at
    sample ``(t + 1) * HOP``): :func:`models.evaluation.evaluate.span_beats` with first frame 0."""
    from models.evaluation.beats import music_beats

    return music_beats(np.asarray(audio, np.float32)[HOP:], SAMPLE_RATE, FPS)


def stretched_beats(times: np.ndarray, start_s: float, rate: float, frames: int) -> np.ndarray:
    """Beat frames (sorted int, ``0 <= f < frames``) in an excerpt from ``start_s`` played at
    ``rate``, of the beats at ``times`` (s) of the whole recording: a beat at recording time
    ``s`` sounds at ``(s - start_s) / rate`` s of the excerpt, the end of pose
    ``(s - start_s) / rate * FPS - 1`` (as :func:`heard_beats` places them)."""
    t = (np.asarray(times, np.float64) - start_s) / rate
    f = np.unique(np.rint(t[t >= 0] * FPS - 1).astype(np.int64))
    return f[(f >= 0) & (f < frames)]


def vary_rate(audio: np.ndarray, rate: Callable[[np.ndarray], np.ndarray], n_fft: int = 2048) -> np.ndarray:
    """``audio`` (n,) at 22050 Hz played at a time-varying rate with pitch kept.

    ``rate(t)``: rate (> 0; 1.25 = 25 % faster) at output times ``t`` (s). A phase vocoder
    with one read position per output STFT frame: output frame ``k`` reads the input at
    ``steps[k] = sum of rate over the frames before k`` (in frames, between two analysis
    frames magnitudes interpolated linearly, phases advanced by the measured phase
    difference), as ``librosa.phase_vocoder`` does for one fixed rate; ``librosa.stft`` /
    ``istft``, hop ``n_fft // 4``. Stops where the input runs out.
    """
    import librosa

    hop = n_fft // 4
    d = librosa.stft(np.asarray(audio, np.float32), n_fft=n_fft, hop_length=hop)
    t_out = np.arange(int(4 * d.shape[1])) * hop / SAMPLE_RATE  # enough output frames for rates >= 0.25
    r = np.asarray(rate(t_out), np.float64)
    if not np.all(r > 0):
        raise DataError("rates must be positive", source="rate")
    steps = np.concatenate([[0.0], np.cumsum(r)[:-1]])
    steps = steps[steps < d.shape[1] - 1]
    phi_advance = hop * np.linspace(0, np.pi, d.shape[0])
    out = np.zeros((d.shape[0], len(steps)), np.complex64)
    phase = np.angle(d[:, 0])
    d = np.pad(d, [(0, 0), (0, 2)])
    for k, step in enumerate(steps):
        i, alpha = int(step), step % 1.0
        a, b = d[:, i], d[:, i + 1]
        out[:, k] = ((1 - alpha) * np.abs(a) + alpha * np.abs(b)) * np.exp(1j * phase)
        dphase = np.angle(b) - np.angle(a) - phi_advance
        phase = phase + phi_advance + dphase - 2 * np.pi * np.round(dphase / (2 * np.pi))
    return librosa.istft(out, hop_length=hop, n_fft=n_fft).astype(np.float32)


def ramp_rate(t: np.ndarray, rates: tuple[float, float] = RAMP_RATES, ramp_s: float = RAMP_S,
              hold_s: float = RAMP_HOLD_S) -> np.ndarray:
    """The ramp's rate at output times ``t`` (s): ``rates[0]`` for ``hold_s``, linearly up to
    ``rates[1]`` over ``ramp_s``, down again over ``ramp_s``, then ``rates[0]``."""
    lo, hi = rates
    u = np.clip((np.asarray(t, np.float64) - hold_s) / ramp_s, 0.0, 2.0)
    return lo + (hi - lo) * np.where(u <= 1.0, u, 2.0 - u)


def _key(path: Path, *parts: object) -> str:
    st = path.stat()
    h = hashlib.sha1("|".join(map(str, (path.resolve(), st.st_size, st.st_mtime_ns, *parts))).encode()).hexdigest()
    return f"{path.stem}-{'-'.join(map(str, parts))}-{h[:10]}"


class AudioCache:
    """Decoded recordings, their tempo and stretched excerpts; stretched audio and tempi are
    kept under ``root`` (``None``: nothing kept), keyed by file (path, size, mtime), excerpt and rate."""

    def __init__(self, root: str | Path | None):
        self.root = Path(root) if root is not None else None
        self._audio: dict[Path, np.ndarray] = {}

    def audio(self, path: Path) -> np.ndarray:
        from models.features.audio_io import load_audio

        path = Path(path)
        if path not in self._audio:
            self._audio[path] = load_audio(path, SAMPLE_RATE)[0]
        return self._audio[path]

    def _file(self, name: str) -> Path | None:
        if self.root is None:
            return None
        self.root.mkdir(parents=True, exist_ok=True)
        return self.root / name

    @staticmethod
    def _write(f: Path, data: np.ndarray | str) -> None:
        """Write ``f`` whole or not at all (a temporary file renamed over it), so a run beside
        another one sharing the cache never reads half a file."""
        fd, tmp = tempfile.mkstemp(prefix=f.name, suffix=".tmp", dir=f.parent)
        try:
            with os.fdopen(fd, "wb") as fh:
                if isinstance(data, str):
                    fh.write(data.encode())
                else:
                    np.save(fh, data)
            os.replace(tmp, f)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)

    def tempo(self, path: Path) -> float:
        f = self._file(_key(Path(path), "tempo") + ".json")
        if f is not None and f.is_file():
            return float(json.loads(f.read_text())["bpm"])
        bpm = recording_tempo(self.audio(path))
        if f is not None:
            self._write(f, json.dumps({"file": str(path), "bpm": bpm}))
        return bpm

    def beats(self, path: Path) -> np.ndarray:
        """Beat times (s) of the whole recording, ``librosa.beat.beat_track`` (hop :data:`HOP`)."""
        import librosa

        f = self._file(_key(Path(path), "beats") + ".json")
        if f is not None and f.is_file():
            return np.asarray(json.loads(f.read_text())["beats"], np.float64)
        _, t = librosa.beat.beat_track(y=self.audio(path), sr=SAMPLE_RATE, hop_length=HOP, units="time")
        if f is not None:
            self._write(f, json.dumps({"file": str(path), "beats": [float(x) for x in t]}))
        return np.asarray(t, np.float64)

    def excerpt(self, path: Path, start_s: float, seconds: float, rate: float) -> np.ndarray:
        """``seconds`` of ``path`` from ``start_s``, time-stretched by ``rate`` (1: as recorded)."""
        import librosa

        a = self.audio(path)
        x = a[int(start_s * SAMPLE_RATE): int((start_s + seconds) * SAMPLE_RATE)]
        if rate == 1.0:
            return x
        f = self._file(_key(Path(path), f"{start_s:g}", f"{seconds:g}", f"x{rate:g}") + ".npy")
        if f is not None and f.is_file():
            return np.load(f)
        y = librosa.effects.time_stretch(x, rate=rate).astype(np.float32)
        if f is not None:
            self._write(f, y)
        return y

    def ramp(self, path: Path, start_s: float, seconds: float) -> np.ndarray:
        """``seconds`` of ``path`` from ``start_s`` played at :func:`ramp_rate` (:func:`vary_rate`)."""
        a = self.audio(path)
        x = a[int(start_s * SAMPLE_RATE): int((start_s + seconds) * SAMPLE_RATE)]
        f = self._file(_key(Path(path), f"{start_s:g}", f"{seconds:g}",
                            f"ramp{RAMP_RATES[0]:g}-{RAMP_RATES[1]:g}-{RAMP_S:g}-{RAMP_HOLD_S:g}") + ".npy")
        if f is not None and f.is_file():
            return np.load(f)
        y = vary_rate(x, ramp_rate)
        if f is not None:
            self._write(f, y)
        return y


# --------------------------------------------------------------------------- the performer


def perform(lm, audio: np.ndarray, seed: int = 0, trace: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(poses (T, P), idle weight after every frame (T,)) of a loaded dance_vq model ``lm``
    (:class:`models.generate.LoadedModel`) on ``audio`` (n,) at 22050 Hz, T = n // HOP:
    features as ``performer generate`` computes them, the live stream pushed frame by frame
    (the same poses as :func:`models.networks.dance_stream.generate` with ``seed``). A
    ``trace`` dict receives ``tempo_bpm``, ``rate`` and ``movement_speed`` (T,): the stream's
    followed tempo, playback rate and the playing movement's own mean joint speed (m/s at its
    own pace: what the choice of movement sets) after every frame, ``rate_asked`` and
    ``rate_capped`` (T,): the playing movement's rate as the tempo asked it and under the speed
    cap, before the speed matching (``DanceStream.rate_split``), and ``codes``: the codes
    drawn, one per movement."""
    from models.features.spectral import extract_features
    from models.networks.dance_stream import DanceStream

    feats = extract_features(np.asarray(audio, np.float32), lm.features)
    stream = DanceStream(lm.model, seed=seed)
    poses = np.empty((len(feats), lm.model.config.pose_dim), np.float32)
    w, tempo, rate, own = (np.empty(len(feats)) for _ in range(4))
    split = np.empty((len(feats), 2))
    for t in range(len(feats)):
        poses[t] = stream.push(feats[t: t + 1])[0]
        w[t], tempo[t], rate[t], own[t] = (stream.idle_weight, stream.tempo_bpm, stream.playback_rate,
                                           stream.movement_speed)
        split[t] = stream.rate_split
    if trace is not None:
        trace.update(tempo_bpm=tempo, rate=rate, movement_speed=own, rate_asked=split[:, 0], rate_capped=split[:, 1],
                     codes=list(stream.codes_drawn))
    return poses, w


def sounding_frames(lm, feats: np.ndarray) -> int:
    """Frames of features ``feats`` (T, D) up to and with the last one louder than the model's
    silence threshold (log energy above ``model.gate[0]``, dB): a recording's trailing silence
    (many end with 1-6 s of it) is the music stopped, where the performer is to idle."""
    col = lm.model.config.energy_col
    loud = np.flatnonzero(feats[:, col] > float(lm.model.gate[0]))
    return int(loud[-1]) + 1 if loud.size else 0


def music_end(lm, feats: np.ndarray, name: str) -> tuple[int, int]:
    """(last sound, end of the music): frames of recording ``name`` (its stem) with features
    ``feats`` (T, D) up to its last sound (:func:`sounding_frames`) and up to where its music
    ends, the earlier of that and :data:`MUSIC_ENDS_S` (applause after the music)."""
    sound = sounding_frames(lm, feats)
    end = min(sound, int(round(MUSIC_ENDS_S[name] * FPS))) if name in MUSIC_ENDS_S else sound
    return sound, end


def positions(poses: np.ndarray) -> np.ndarray:
    from models.evaluation.evaluate import positions as fk_positions

    return fk_positions(poses)


# --------------------------------------------------------------------------- the sets


@dataclass
class Options:
    """What the sets run on. ``dwm``: the DWM dataset (its validation songs join the stretch
    set); ``music``, ``speech``: the recordings directories; ``seeds``: the sampling seeds the
    stretch set runs at, its figures the mean over them (:data:`SEEDS`); ``ramp_seeds``: the
    ramp's (:data:`RAMP_SEEDS`); ``quick``: a few songs, shorter, one seed."""

    dwm: str | Path | None = None
    music: str | Path | None = None
    speech: str | Path | None = None
    cache_dir: str | Path | None = ".cache/listening"
    excerpt_s: float = 45.0
    excerpt_start_s: float = 10.0
    max_songs: int | None = None
    ramp_song: str | None = None
    presence_max_s: float | None = None
    speech_song_s: float = 20.0
    seeds: tuple[int, ...] = SEEDS
    ramp_seeds: tuple[int, ...] = RAMP_SEEDS
    quick: bool = False
    progress: bool = True
    sets: tuple[str, ...] = ("stretch", "ramp", "presence")

    def __post_init__(self) -> None:
        self.seeds = tuple(int(x) for x in self.seeds)
        self.ramp_seeds = tuple(int(x) for x in self.ramp_seeds)
        if not self.seeds or not self.ramp_seeds:
            raise DataError("at least one seed", source="listening options")
        if self.quick:
            self.seeds = self.seeds[:1]
            self.ramp_seeds = self.ramp_seeds[:1]
            self.max_songs = self.max_songs or 3
            self.excerpt_s = min(self.excerpt_s, 25.0)
            self.presence_max_s = self.presence_max_s or 30.0


def candidates(opts: Options) -> list[Path]:
    """Recordings of the stretch set before the tempo check: the DWM validation songs
    (``models.data.split``), then every file of ``opts.music``."""
    out: list[Path] = []
    if opts.dwm is not None:
        from models.data.dwm import dance_dirs, load_dance
        from models.data.split import split_names

        _, val = split_names([d.name for d in dance_dirs(opts.dwm)])
        out += [Path(load_dance(Path(opts.dwm) / n).audio_path) for n in val]
    if opts.music is not None:
        out += music_files(opts.music)
    return out


def music_files(directory: str | Path) -> list[Path]:
    d = Path(directory)
    files = sorted(p for p in d.iterdir() if p.suffix.lower() in (".ogg", ".wav", ".flac", ".mp3")) if d.is_dir() else []
    if not files:
        raise DataError("no recordings (.ogg, .wav, .flac, .mp3) found", source=d)
    return files


def song_name(path: Path) -> str:
    return path.parent.name if path.name == "audio.mp3" else path.stem


def _bar(items, desc: str, opts: Options):
    from tqdm import tqdm

    return tqdm(items, desc=desc, unit="run", disable=not opts.progress, leave=False)


def stretch_songs(cache: AudioCache, opts: Options) -> list[tuple[Path, float]]:
    """(recording, whole-file bpm) of the candidates in :data:`TEMPO_RANGE`, at most ``opts.max_songs``."""
    songs = []
    for p in _bar(candidates(opts), "tempo of the recordings", opts):
        bpm = cache.tempo(p)
        if TEMPO_RANGE[0] <= bpm <= TEMPO_RANGE[1]:
            songs.append((p, bpm))
    return songs[: opts.max_songs] if opts.max_songs else songs


def _excerpt_window(cache: AudioCache, path: Path, opts: Options) -> tuple[float, float]:
    dur = len(cache.audio(path)) / SAMPLE_RATE
    seconds = min(opts.excerpt_s, dur)
    start = min(opts.excerpt_start_s, max(0.0, dur - seconds))
    return start, seconds


def score_motion(poses: np.ndarray, beats: np.ndarray) -> dict[str, float]:
    """The stretch set's figures of one performance from :data:`SETTLE_S` on (beats: frames of the whole)."""
    skip = int(SETTLE_S * FPS)
    pos = positions(poses[skip:])
    b = np.asarray(beats) - skip
    hit, half = beat_hits(pos, b[b >= 0])
    return {"speed": mean_speed(pos), "centroid_hz": frequency_centroid(pos), "kin_bpm": kinematic_bpm(pos),
            "amp_m": dance_amplitude(pos), "hit": hit, "hit_half": half}


def reference_beats(cache: AudioCache, path: Path, start_s: float, rate: float, frames: int) -> np.ndarray:
    """The music's beat frames (sorted int, < ``frames``) in the excerpt of ``path`` from
    ``start_s`` played at ``rate``: the whole recording's (:meth:`AudioCache.beats`) moved
    by the stretch (:func:`stretched_beats`), the same musical beats at every rate."""
    return stretched_beats(cache.beats(path), start_s, rate, frames)


def stretch_set(lm, cache: AudioCache, songs: list[tuple[Path, float]], opts: Options) -> list[dict]:
    """Per song: its bpm, excerpt, and :func:`score_motion` at every rate of :data:`STRETCH_RATES`,
    against the recording's beats moved by the stretch (:func:`stretched_beats`): ``librosa``
    on each stretched excerpt picks its own metrical level (on the validation rumba DANCE_R_5
    82 bpm at 1.0x and 129 at 0.8x, a 106-bpm song), and the hit rate, a share of the motion's
    speed dips, rises and falls with the reference's beats per minute."""
    rows = []
    jobs = [(p, bpm, r, seed) for p, bpm in songs for r in STRETCH_RATES for seed in opts.seeds]
    by_song: dict[Path, dict] = {}
    for p, bpm, r, seed in _bar(jobs, f"stretch set {lm.path.name}", opts):
        start, seconds = _excerpt_window(cache, p, opts)
        y = cache.excerpt(p, start, seconds, r)
        trace: dict = {}
        poses, _ = perform(lm, y, seed, trace)
        row = by_song.setdefault(p, {"song": song_name(p), "bpm": bpm, "start_s": start, "seconds": seconds,
                                     "by_seed": {}})
        got = score_motion(poses, reference_beats(cache, p, start, r, len(poses)))
        # the chosen movements' own speed (m/s, at their own pace), from SETTLE_S on, as score_motion
        got["movement_speed"] = float(trace["movement_speed"][int(SETTLE_S * FPS):].mean())
        row["by_seed"].setdefault(str(seed), {"rates": {}})["rates"][f"{r:g}"] = got
    for p, _ in songs:
        row = by_song[p]
        runs = [x["rates"] for x in row["by_seed"].values()]
        row["rates"] = {k: {f: float(np.mean([x[k][f] for x in runs])) for f in runs[0][k]} for k in runs[0]}
        row.update(_ratios(row["rates"]))
        for x in row["by_seed"].values():  # each seed's own ratios, for the spread over seeds
            x.update(_ratios(x["rates"]))
        rows.append(row)
    return rows


def _ratios(rates: dict[str, dict]) -> dict:
    """A song's 1.25x-over-0.8x ratios, and its band amplitudes over 1.0x's, from its per-rate figures."""
    lo, mid, hi = (rates[f"{r:g}"] for r in STRETCH_RATES)
    return {"speed_ratio": hi["speed"] / max(lo["speed"], 1e-12),
            "movement_speed_ratio": hi["movement_speed"] / max(lo["movement_speed"], 1e-12),
            "centroid_ratio": hi["centroid_hz"] / max(lo["centroid_hz"], 1e-12),
            "kin_bpm_ratio": hi["kin_bpm"] / max(lo["kin_bpm"], 1e-12),
            "amp_rel": {k: rates[k]["amp_m"] / max(mid["amp_m"], 1e-12) for k in rates}}


def ramp_song(cache: AudioCache, songs: list[tuple[Path, float]], opts: Options) -> tuple[Path, float] | None:
    """The ramp's recording: ``opts.ramp_song`` (a stem or directory name among the stretch set's
    candidates) or the first song of the stretch set long enough for the whole ramp (None: none is)."""
    need = (RAMP_HOLD_S + 2 * RAMP_S) * RAMP_RATES[1] + 1.0
    if opts.ramp_song:
        for p in candidates(opts):
            if opts.ramp_song in (song_name(p), p.name):
                return p, cache.tempo(p)
        raise DataError(f"no recording named {opts.ramp_song!r} among the candidates", source="--ramp-song")
    for p, bpm in songs:
        if len(cache.audio(p)) / SAMPLE_RATE >= need:
            return p, bpm
    return None


def ramp_audio(cache: AudioCache, path: Path, opts: Options) -> tuple[np.ndarray, float]:
    """(the ramp's audio (n,) at 22050 Hz, :func:`ramp_rate` from its start; the second of
    ``path`` it starts at)."""
    total = RAMP_HOLD_S + 2 * RAMP_S
    source_s = RAMP_HOLD_S * RAMP_RATES[0] + RAMP_S * (RAMP_RATES[0] + RAMP_RATES[1]) + 2.0
    start = min(opts.excerpt_start_s, max(0.0, len(cache.audio(path)) / SAMPLE_RATE - source_s))
    return cache.ramp(path, start, source_s)[: int(total * SAMPLE_RATE)], start


def ramp(lm, cache: AudioCache, song: tuple[Path, float], opts: Options) -> dict:
    """The ramp's figures and curves: ``tempo_bpm`` (real tempo: the song's bpm x
    :func:`ramp_rate`) and ``speed`` (mean joint speed, m/s), both per frame and smoothed over
    :data:`SMOOTH_S`; their :func:`lagged_correlation` from the end of the hold on (and, to
    see where it is lost, the followed tempo's and the playback rate's, ``follower_corr`` and
    ``rate_corr``; ``followed_bpm``, smoothed, is the curve; ``follows_tempo``: False for a
    model that plays every movement at its own pace); the largest bone rotation per
    frame after :data:`SETTLE_S`. At each of ``opts.ramp_seeds``: ``corr``, ``corr_lag0`` and the
    three diagnostics are the means over the seeds of each one's own (``corr_seeds``, one
    performer's speed each, not the speed averaged over performers), ``lag_s`` and
    ``follower_lag_s`` (the followed tempo's lag behind the real one at its best correlation:
    how late a tempo change is followed) the medians, ``max_step_deg`` the largest; the
    curves are the first seed's."""
    path, bpm = song
    y, start = ramp_audio(cache, path, opts)
    a, lags = int(RAMP_HOLD_S * FPS), int(MAX_LAG_S * FPS)
    runs = []
    for seed in opts.ramp_seeds:
        trace: dict = {}
        poses, _ = perform(lm, y, seed, trace)
        t = (np.arange(len(poses)) + 1) / FPS
        tempo = smooth(bpm * ramp_rate(t))
        speed = smooth(motion_speed(positions(poses)))
        own = smooth(trace["movement_speed"])
        corr, lag, corr0 = lagged_correlation(tempo[a:], speed[a:], lags)
        follower_corr, follower_lag, _ = lagged_correlation(tempo[a:], smooth(trace["tempo_bpm"])[a:], lags)
        runs.append({
            "corr": corr, "lag": lag, "corr_lag0": corr0,
            # where the speed's correlation is lost: the followed tempo, the playback rate, the choice (best lag each)
            "follower_corr": follower_corr, "follower_lag": follower_lag,
            "rate_corr": lagged_correlation(tempo[a:], smooth(trace["rate"])[a:], lags)[0],
            "movement_corr": lagged_correlation(tempo[a:], own[a:], lags)[0],
            "own": own, "step": float(bone_steps_deg(poses[int(SETTLE_S * FPS):]).max()),
            "t": t, "tempo": tempo, "speed": speed, "trace": trace})
    first = runs[0]
    mean = lambda key: float(np.mean([r[key] for r in runs]))  # noqa: E731
    own = np.concatenate([r["own"][a:] for r in runs])
    check = ramp_audio_check(y, bpm)
    return {"song": song_name(path), "bpm": bpm, "start_s": start, "corr": mean("corr"),
            "lag_s": float(np.median([r["lag"] for r in runs])) / FPS, "corr_lag0": mean("corr_lag0"),
            "corr_seeds": [r["corr"] for r in runs], "follower_corr": mean("follower_corr"),
            "follower_lag_s": float(np.median([r["follower_lag"] for r in runs])) / FPS,
            "rate_corr": mean("rate_corr"), "movement_corr": mean("movement_corr"),
            "movement_speed_range": [float(own.min()), float(own.max())],
            "max_step_deg": max(r["step"] for r in runs), **check, "time_s": first["t"].tolist(),
            "tempo_bpm": first["tempo"].tolist(), "speed": first["speed"].tolist(),
            "followed_bpm": smooth(first["trace"]["tempo_bpm"]).tolist(),
            "follows_tempo": bool(np.ptp(first["trace"]["rate"]) > 0)}


def ramp_audio_check(y: np.ndarray, bpm: float) -> dict[str, float]:
    """Does the ramp's audio ``y`` (n,) at 22050 Hz play at ``bpm`` x :func:`ramp_rate`? The local
    tempo of ``librosa.feature.tempo`` (``aggregate=None``: one estimate per onset frame from
    its ~9-s tempogram window, prior centred on ``bpm``) between 8 s and 6 s before the end:
    ``audio_tempo_corr`` (its correlation with the intended tempo) and ``audio_tempo_err``
    (median relative error)."""
    import librosa

    hop = 512
    env = librosa.onset.onset_strength(y=np.asarray(y, np.float32), sr=SAMPLE_RATE, hop_length=hop)
    local = librosa.feature.tempo(onset_envelope=env, sr=SAMPLE_RATE, hop_length=hop, aggregate=None,
                                  start_bpm=bpm, prior=None)
    t = librosa.times_like(env, sr=SAMPLE_RATE, hop_length=hop)
    want = bpm * ramp_rate(t)
    keep = (t > 8.0) & (t < t[-1] - 6.0)
    return {"audio_tempo_corr": float(np.corrcoef(local[keep], want[keep])[0, 1]),
            "audio_tempo_err": float(np.median(np.abs(local[keep] / want[keep] - 1)))}


def settle_back(w: np.ndarray, start: int, end: int, nxt: int) -> dict[str, float | None]:
    """Idle weights ``w (T,)`` around a non-music part ``[start, end)`` followed by music up to
    ``nxt``: ``settle_s`` (from ``start`` to fully idle, w >= 1; None: never), ``held`` (share of
    frames from then to ``end`` with w > :data:`IDLE_THRESHOLD`; 0 if never idle), ``back_s`` (from
    ``end`` to fully dancing, w <= 0; None: never, or never idle), as idle_gate.py counts them."""
    idle = np.flatnonzero(w[start:end] >= 1.0)
    back = np.flatnonzero(w[end:nxt] <= 0.0)
    at = start + int(idle[0]) if idle.size else None
    return {"settle_s": None if at is None else (at - start + 1) / FPS,
            "held": 0.0 if at is None else float(np.mean(w[at:end] > IDLE_THRESHOLD)),
            "back_s": None if at is None or not back.size else (int(back[0]) + 1) / FPS}


def presence(lm, cache: AudioCache, speech_song: Path | None, opts: Options) -> dict:
    """``music``: per recording of ``opts.music``, the idle fraction (w > :data:`IDLE_THRESHOLD`)
    after :data:`SETTLE_S`, also only up to its last sound (``idle_sounding``, :func:`sounding_frames`;
    ``silent_tail_s``: the seconds after it); ``speech``: per recording of ``opts.speech``, ``speech_song`` for
    ``opts.speech_song_s``, the speech scaled to the song's RMS, the song's next
    ``opts.speech_song_s``, scored by :func:`settle_back`."""
    from models.features.spectral import extract_features

    out: dict[str, list] = {"music": [], "speech": []}
    files = music_files(opts.music) if opts.music is not None else []
    for p in _bar(files, f"presence {lm.path.name}", opts):
        a = cache.audio(p)
        if opts.presence_max_s:
            a = a[: int(opts.presence_max_s * SAMPLE_RATE)]
        _, w = perform(lm, a, opts.seeds[0])
        s = w[int(SETTLE_S * FPS):]
        sound, end = music_end(lm, extract_features(a, lm.features), p.stem)
        out["music"].append({"recording": p.stem, "seconds": len(a) / SAMPLE_RATE,
                             "idle": float(np.mean(s > IDLE_THRESHOLD)),
                             "idle_sounding": float(np.mean(w[int(SETTLE_S * FPS): end] > IDLE_THRESHOLD))
                             if end > int(SETTLE_S * FPS) else 0.0,  # no music after the first 3 s
                             "silent_tail_s": (len(w) - sound) / FPS, "after_music_s": (sound - end) / FPS})
    if opts.speech is None or speech_song is None:
        return out
    song = cache.audio(speech_song)
    n = int(opts.speech_song_s * SAMPLE_RATE)
    n -= n % HOP
    start = min(int(opts.excerpt_start_s * SAMPLE_RATE), max(0, len(song) - 2 * n))
    first, second = song[start: start + n], song[start + n: start + 2 * n]
    level = rms(np.concatenate([first, second]))
    for p in _bar(music_files(opts.speech), "speech between songs", opts):
        sp = cache.audio(p)
        sp = sp[: len(sp) - len(sp) % HOP] * (level / max(rms(sp), 1e-9))
        _, w = perform(lm, np.concatenate([first, sp, second]).astype(np.float32), opts.seeds[0])
        a, b = n // HOP, (n + len(sp)) // HOP
        out["speech"].append({"recording": p.stem, "song": song_name(speech_song), "speech_s": len(sp) / SAMPLE_RATE,
                              **settle_back(w, a, b, len(w))})
    return out


# --------------------------------------------------------------------------- summary


def summary(result: dict) -> dict[str, float | None]:
    """The target figures (keys of :data:`TARGETS`, plus means) of one model's :func:`run` result."""
    s: dict[str, float | None] = {}
    rows = result.get("stretch") or []
    if rows:
        mean = lambda xs: float(np.mean(xs))  # noqa: E731
        s["speed_ratio"] = mean([r["speed_ratio"] for r in rows])
        s["movement_speed_ratio"] = mean([r.get("movement_speed_ratio", float("nan")) for r in rows])
        s["centroid_ratio"] = mean([r["centroid_ratio"] for r in rows])
        s["kin_bpm_ratio"] = mean([r["kin_bpm_ratio"] for r in rows])
        for k in (f"{r:g}" for r in STRETCH_RATES):
            s[f"amp_{k}"] = mean([r["amp_rel"][k] for r in rows])
            s[f"hit_{k}"] = mean([r["rates"][k]["hit"] for r in rows])
            s[f"hit_half_{k}"] = mean([r["rates"][k]["hit_half"] for r in rows])
            s[f"hit_ratio_{k}"] = s[f"hit_{k}"] / max(s[f"hit_half_{k}"], 1e-12)
        ks = [f"{r:g}" for r in STRETCH_RATES]
        s["amp_min"] = min(s[f"amp_{k}"] for k in ks)
        s["amp_max"] = max(s[f"amp_{k}"] for k in ks)
        s["hit_min"] = min(s[f"hit_{k}"] for k in ks)
        s["hit_half_min"] = min(s[f"hit_ratio_{k}"] for k in ks)
    if result.get("ramp"):
        r = result["ramp"]
        s["ramp_corr"], s["ramp_max_step_deg"] = r["corr"], r["max_step_deg"]
        corr_target = next(thr for k, _, _, thr in TARGETS if k == "ramp_corr")
        s["ramp_lag_s"] = r["lag_s"] if r["corr"] >= corr_target else None  # NOT_APPLICABLE
        if "follower_corr" in r:  # how late the followed tempo is (issue 43), judged where it follows
            s["ramp_follower_corr"] = r["follower_corr"]
            s["ramp_follower_lag_s"] = r["follower_lag_s"] if r["follower_corr"] >= corr_target else None
    pres = result.get("presence") or {}
    if pres.get("music"):
        s["idle_max"] = max(m["idle"] for m in pres["music"])
        if all("idle_sounding" in m for m in pres["music"]):
            s["idle_sounding_max"] = max(m["idle_sounding"] for m in pres["music"])
    if pres.get("speech"):
        sp = pres["speech"]
        worst = lambda key: None if any(x[key] is None for x in sp) else max(x[key] for x in sp)  # noqa: E731
        s["speech_settle_s"] = worst("settle_s")
        s["speech_held"] = min(x["held"] for x in sp)
        s["speech_back_s"] = worst("back_s")
    return s


#: Targets whose None means "nothing to judge" (n/a), with why: dancing again when it never
#: went idle; the lag of a correlation that is not there (the best lag of a correlation under
#: its target says nothing of how late the speed follows).
NOT_APPLICABLE: dict[str, str] = {"speech_back_s": "never idle", "ramp_lag_s": "correlation under 0.7",
                                  "ramp_follower_lag_s": "correlation under 0.7"}


def verdict(key: str, value: float | None) -> str:
    """PASS, FAIL (None: the event never happened), "n/a" (:data:`NOT_APPLICABLE`) or "" for a
    key that is no target."""
    for k, _, op, thr in TARGETS:
        if k == key:
            if value is None or (isinstance(value, float) and math.isnan(value)):
                return "n/a" if key in NOT_APPLICABLE else "FAIL"
            return "PASS" if (value >= thr if op == ">=" else value <= thr) else "FAIL"
    return ""


def run(checkpoints: Sequence[str | Path | None], opts: Options, log=print, only_dance_vq: bool = False) -> dict:
    """Every set of ``opts.sets`` for each dance_vq checkpoint (None: the packaged default);
    another model kind raises PerformerError, or with ``only_dance_vq`` is left out (logged).
    Returns ``{"options": ..., "models": {name: {"checkpoint", "stretch", "ramp", "presence", "summary"}}}``."""
    from models.errors import PerformerError
    from models.generate import load_model

    loaded = []
    for lm in (load_model(c) for c in checkpoints):
        if getattr(lm.model, "takes_style", False):
            loaded.append(lm)
        elif only_dance_vq:
            log(f"listening: {lm.path} is a {lm.name!r} model; the listening sets run dance_vq models only")
        else:
            raise PerformerError(f"{lm.path} is a {lm.name!r} model; the listening sets run dance_vq models")
    if not loaded:
        return {"options": {}, "models": {}}
    cache = AudioCache(opts.cache_dir)
    songs = stretch_songs(cache, opts) if {"stretch", "ramp", "presence"} & set(opts.sets) else []
    if "stretch" in opts.sets:
        if not songs:
            raise DataError(f"no recording between {TEMPO_RANGE[0]:g} and {TEMPO_RANGE[1]:g} bpm", source="stretch set")
        log(f"stretch set: {len(songs)} songs in {TEMPO_RANGE[0]:g}-{TEMPO_RANGE[1]:g} bpm: "
            + ", ".join(f"{song_name(p)} ({b:.0f})" for p, b in songs))
    rsong = ramp_song(cache, songs, opts) if {"ramp", "presence"} & set(opts.sets) else None
    if "ramp" in opts.sets and rsong is None:
        log("ramp: no song of the stretch set is long enough; the ramp is left out")
    # the speech plays inside the ramp's song, whichever sets run (the same figures alone or with the others)
    speech_song = rsong[0] if rsong else (songs[0][0] if songs else None)
    if speech_song is None and "presence" in opts.sets and opts.music is not None:
        speech_song = music_files(opts.music)[0]
    models: dict[str, dict] = {}
    for lm in loaded:
        try:
            shown = lm.path.resolve().relative_to(Path.cwd().resolve())
        except ValueError:
            shown = lm.path
        name = f"{lm.name} ({shown})"
        if name in models:  # the same file twice
            name += f" #{sum(n.startswith(name) for n in models) + 1}"
        res: dict = {"checkpoint": str(lm.path)}
        if "stretch" in opts.sets:
            res["stretch"] = stretch_set(lm, cache, songs, opts)
        if "ramp" in opts.sets and rsong is not None:
            res["ramp"] = ramp(lm, cache, rsong, opts)
        if "presence" in opts.sets:
            res["presence"] = presence(lm, cache, speech_song, opts)
        res["summary"] = summary(res)
        models[name] = res
    o = asdict(opts)
    return {"options": {k: (str(v) if isinstance(v, Path) else v) for k, v in o.items()}, "models": models}


# --------------------------------------------------------------------------- report


def _fmt(v: float | None, digits: int = 2) -> str:
    return "never" if v is None else f"{v:.{digits}f}"


def markdown(result: dict, command: str | None = None) -> str:
    """Markdown tables of :func:`run`'s result: the targets with PASS/FAIL per model, then
    per-song stretch figures, the ramp and the presence rows."""
    models = result["models"]
    names = list(models)
    lines = []
    if command:
        lines += ["```", command, "```", ""]
    if not names:
        return "\n".join(lines + ["No dance_vq checkpoint: no listening figures."]) + "\n"
    lines += ["| target | " + " | ".join(names) + " |", "| --- | " + " | ".join("---:" for _ in names) + " |"]
    for key, desc, op, thr in TARGETS:
        cells = []
        for n in names:
            s = models[n]["summary"]
            v = verdict(key, s.get(key))
            cells.append("n/a" if key not in s else f"n/a ({NOT_APPLICABLE[key]})" if v == "n/a" else f"{_fmt(s[key])} {v}")
        lines.append(f"| {desc} ({op} {thr:g}) | " + " | ".join(cells) + " |")
    for n in names:
        m, s = models[n], models[n]["summary"]
        lines += ["", f"**{n}**", ""]
        if m.get("stretch"):
            rates = [f"{r:g}" for r in STRETCH_RATES]
            lines += ["| song | bpm | speed (m/s) " + " / ".join(rates) + " | ratio | centroid (Hz) | ratio "
                      "| kin. bpm | ratio | amplitude / 1.0x | beat hit | half-shifted hit |",
                      "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
            for r in m["stretch"]:
                x = r["rates"]
                j = lambda key, d=2: " / ".join(f"{x[k][key]:.{d}f}" for k in rates)  # noqa: E731
                lines.append(f"| {r['song']} | {r['bpm']:.0f} | {j('speed')} | {r['speed_ratio']:.2f} "
                             f"| {j('centroid_hz')} | {r['centroid_ratio']:.2f} | {j('kin_bpm', 0)} "
                             f"| {r['kin_bpm_ratio']:.2f} | " + " / ".join(f"{r['amp_rel'][k]:.2f}" for k in rates)
                             + f" | {j('hit')} | {j('hit_half')} |")
            lines.append(f"| **mean** | | | {s['speed_ratio']:.2f} | | {s['centroid_ratio']:.2f} | | "
                         f"{s['kin_bpm_ratio']:.2f} | " + " / ".join(f"{s[f'amp_{k}']:.2f}" for k in rates)
                         + " | " + " / ".join(f"{s[f'hit_{k}']:.2f}" for k in rates) + " | "
                         + " / ".join(f"{s[f'hit_half_{k}']:.2f}" for k in rates) + " |")
            seeds = list(m["stretch"][0].get("by_seed", {}))
            if len(seeds) > 1:  # the spread: the same figures at each seed alone
                per = {sd: summary({"stretch": [{**r, **r["by_seed"][sd]} for r in m["stretch"]]}) for sd in seeds}
                lines += ["", f"Each figure is the mean over seeds {', '.join(seeds)}; at each seed alone: speed ratio "
                          + " / ".join(f"{per[sd]['speed_ratio']:.2f}" for sd in seeds) + ", centroid ratio "
                          + " / ".join(f"{per[sd]['centroid_ratio']:.2f}" for sd in seeds) + ", lowest beat hit rate "
                          + " / ".join(f"{per[sd]['hit_min']:.2f}" for sd in seeds) + ", lowest hit over half-shifted "
                          + " / ".join(f"{per[sd]['hit_half_min']:.2f}" for sd in seeds) + "."]
            lines += ["", "The chosen movements' own speed (at their own pace), 1.25x over 0.8x: "
                      + ", ".join(f"{r['song']} {r['movement_speed_ratio']:.2f}" for r in m["stretch"]
                                  if "movement_speed_ratio" in r)
                      + f"; mean {s.get('movement_speed_ratio', float('nan')):.2f} (1: the choice does not "
                      "follow the tempo; the speed ratio over it is what the playback rate adds)."]
        if m.get("ramp"):
            r = m["ramp"]
            each = np.asarray(r.get("corr_seeds", []))
            if len(each) < 2:
                per_seed = ""
            elif len(each) <= 6:
                per_seed = f" (over {len(each)} seeds: at each seed " + ", ".join(f"{c:.2f}" for c in each) + ")"
            else:  # too many to list: their spread
                per_seed = (f" (over {len(each)} seeds, standard error {each.std(ddof=1) / np.sqrt(len(each)):.2f}; "
                            f"at one seed median {np.median(each):.2f}, 10th-90th percentile "
                            f"{np.percentile(each, 10):.2f}-{np.percentile(each, 90):.2f}, lowest {each.min():.2f})")
            lines += ["", f"Ramp on {r['song']} ({r['bpm']:.0f} bpm as recorded): correlation {r['corr']:.2f}{per_seed} at "
                      f"lag {r['lag_s']:.2f} s ({r['corr_lag0']:.2f} at lag 0), largest bone rotation "
                      f"{r['max_step_deg']:.1f} deg a frame. Against the real tempo, the followed tempo "
                      f"correlates {r.get('follower_corr', float('nan')):.2f} at a lag of {r.get('follower_lag_s', float('nan')):.2f} s "
                      "(the tempo changes, followed that much later), the playback rate "
                      f"{r.get('rate_corr', float('nan')):.2f}, and the chosen movements' own speed "
                      f"{r.get('movement_corr', float('nan')):.2f} ("
                      + " to ".join(f"{v:.2f}" for v in r.get("movement_speed_range", [float("nan")] * 2))
                      + " m/s over 4 s, at their own pace). The ramp's audio: local tempo (librosa's tempogram) against "
                      f"the intended tempo, correlation {r['audio_tempo_corr']:.2f}, median error "
                      f"{100 * r['audio_tempo_err']:.1f} %."]
        pres = m.get("presence") or {}
        if pres.get("music"):
            lines += ["", "| recording | s | idle after 3 s, to the file's end | silent end (s) | applause before it (s) "
                          "| idle after 3 s, to the end of the music |",
                      "| --- | ---: | ---: | ---: | ---: | ---: |"]
            lines += [f"| {x['recording']} | {x['seconds']:.0f} | {100 * x['idle']:.1f} % | "
                      f"{x.get('silent_tail_s', math.nan):.1f} | {x.get('after_music_s', 0.0):.1f} | "
                      f"{100 * x.get('idle_sounding', math.nan):.1f} % |" for x in pres["music"]]
        if pres.get("speech"):
            lines += ["", "| speech between songs | settle (s) | idle held | back (s) |", "| --- | ---: | ---: | ---: |"]
            lines += [f"| {x['recording']} ({x['speech_s']:.0f} s) in {x['song']} | {_fmt(x['settle_s'])} | "
                      f"{x['held']:.2f} | {'n/a' if x['settle_s'] is None else _fmt(x['back_s'])} |" for x in pres["speech"]]
    return "\n".join(lines) + "\n"


def verdict_lines(result: dict) -> list[str]:
    """One ``PASS``/``FAIL`` line per target and model."""
    out = []
    for n, m in result["models"].items():
        for key, desc, op, thr in TARGETS:
            if key in m["summary"]:
                v = m["summary"][key]
                shown = f"n/a ({NOT_APPLICABLE[key]})" if verdict(key, v) == "n/a" else _fmt(v)
                out.append(f"{verdict(key, v):4}  {desc} {op} {thr:g}: {shown}  [{n}]")
    return out

"""Record the web viewer: the real dancer and a checkpoint's performer side by side, same music (GIF).

Two real WebSocket servers (``realtime.ws_server.WebSocketSink``, serving
``clients/web/dist`` exactly as ``performer run --ws`` does) each stream one pose array
to its own viewer page in headless Chromium: on the left the real dance's canonical
poses from the training corpus (``models.data.corpus.build_corpus``: in place,
facing +Z, the form the models learn), on the right what the checkpoint generates from
the same clip's features (``models.generate.run_model``, as ``performer generate``
runs it). Both arrays share the 30 fps grid of the clip, so frame t of each side is
the same instant of the song.

The pages are driven frame by frame, not in real time: every 30 fps pose is sent to
both pages, the script waits until each page has received and drawn it (two animation
frames after it arrived), and every (30 / --fps)-th frame is screenshotted. The video
is therefore smooth and the same on a busy machine as on an idle one; the script checks
at the end that each page applied every frame exactly once. The viewers' hand and foot
trails (1.5 s) are primed with the 45 frames before --start-s, and the pages' HUD panels
are hidden (their rates and delays mean nothing when frames are stepped). Labels, the
song time and a beat marker (librosa's beat tracker on the song, lit for 0.1 s per beat)
are drawn around the pictures; the GIF is silent.

With ``--tempo A,B`` both sides are the checkpoint's performer on the same song
time-stretched to two rates with pitch kept (``librosa.effects.time_stretch`` of the song
up to the recorded span; ``--audio`` takes another recording than the dance's song): both
pictures cover the same seconds of wall clock from the moment ``--start-s`` of the
unstretched song, so the faster side hears more of the song; each side has its own beat
marker (the beats of the stretched audio it heard) and song position::

    .venv/bin/python benchmarks/studies/viewer_video.py --tempo 0.8,1.25 --dance DANCE_W_5 --start-s 40 \\
        --seconds 8 --fps 15 --out docs/img/tempo_side_by_side.gif

With ``--stage WxD`` the performer travels on that stage and the real dancer as recorded (its
travel and heading, centred on the recorded span), the stage drawn on both floors and each
camera following its dancer (README's picture)::

    .venv/bin/python benchmarks/studies/viewer_video.py --dance DANCE_W_5 --start-s 40 --seconds 10 \\
        --fps 10 --stage 6x5 --out docs/img/stage_side_by_side.gif

Needs Debian's chromium (``apt-get install chromium``; ``$PERFORMER_CHROMIUM`` names
another binary) and the playwright Python package (``pip install -e '.[dev]'``)::

    .venv/bin/python benchmarks/studies/viewer_video.py --checkpoint models/assets/default.pt \\
        --data ../shared/data/dwm --dance DANCE_W_5 --start-s 40 --seconds 10 --fps 15 \\
        --out docs/img/dance_side_by_side_before.gif
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(REPO))

from models.errors import PerformerError  # noqa: E402
from models.timebase import FPS  # noqa: E402

CHROMIUM = Path(os.environ.get("PERFORMER_CHROMIUM", "/usr/bin/chromium"))
CHROMIUM_ARGS = [  # as tests/test_web_client.py launches it
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]
TRAIL_FRAMES = 45  # clients/web/src/main.js: the hand/foot trails' length (1.5 s)
BEAT_LIT_S = 0.1  # the beat marker stays lit this long after each beat
HIDE_HUD = ".panel { display: none !important; }"
BG = (27, 31, 41)  # the viewer's background (#1b1f29)
FG, DIM, BEAT = (216, 222, 233), (138, 147, 163), (232, 200, 106)  # the viewer's HUD colours
LINE, UNLIT = (89, 98, 122), (57, 64, 77)  # separator, beat marker off


@dataclass
class Tracks:
    """What the two pages show: poses (T, POSE_DIM) on the clip's 30 fps grid, and their context."""

    real: np.ndarray
    generated: np.ndarray
    start: int  # clip frame of the first recorded picture
    frames: int  # 30 fps frames recorded (from start)
    first_song_frame: int  # song frame of clip frame 0 (Clip.first_frame)
    dance: str
    style: str
    checkpoint: str  # its file name, and the energy when not 1
    model: str
    beats: np.ndarray  # song frames (30 fps) of music beats
    split: str  # "validation" or "training": the dance's side of models.data.split
    rates: tuple[float, float] | None = None  # --tempo: the two sides' stretch rates (real, generated: both generated)
    side_beats: tuple[np.ndarray, np.ndarray] | None = None  # --tempo: each side's beat frames on its own grid
    tempo_start_s: float = 0.0  # --tempo: the unstretched song's time at frame ``start`` of both sides
    stage: tuple[float, float] | None = None  # --stage: drawn on both floors; the dancer travels as recorded

    def song_time(self, t: int) -> float:
        """Audio time (s) clip frame ``t`` describes: the end of its feature frame."""
        return (self.first_song_frame + t + 1) / FPS


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", default=None, help="generating checkpoint (default: models/assets/default.pt)")
    p.add_argument("--library", metavar="FILE.npz", help="the performer dances this motion library "
                   "(performer run --library; docs/library.md)")
    p.add_argument("--data", default=os.environ.get("PERFORMER_DATA", str(REPO.parent / "shared" / "data" / "dwm")),
                   help="the dwm dataset directory (default: $PERFORMER_DATA or ../shared/data/dwm)")
    p.add_argument("--dance", default="DANCE_W_5",
                   help="dance whose song and motion capture are shown (default: DANCE_W_5, a validation dance)")
    p.add_argument("--start-s", type=float, default=40.0,
                   help="song time (s, from the start of the audio file) of the first picture (default: 40)")
    p.add_argument("--seconds", type=float, default=10.0, help="length of the recording in seconds (default: 10)")
    p.add_argument("--fps", type=float, default=15.0, help="pictures per second, at most 30 (default: 15)")
    p.add_argument("--size", default="480x360", metavar="WxH", help="one viewer's picture size (default: 480x360)")
    p.add_argument("--out", default="out/viewer_video.gif", help="output GIF (default: out/viewer_video.gif)")
    p.add_argument("--cache", default=".cache/corpus", help="corpus cache directory (default: .cache/corpus)")
    p.add_argument("--energy", type=float, default=1.0,
                   help="the generating model's energy control, 0..2 (default 1: as the music asks; dance_vq "
                        "models only; docs/show.md, \"Energy\")")
    p.add_argument("--tempo", metavar="A,B",
                   help="two stretch rates (e.g. 0.8,1.25): the performer on the song at each rate, side by side")
    p.add_argument("--audio", metavar="FILE", help="--tempo: a recording to stretch instead of --dance's song")
    p.add_argument("--stage", metavar="WxD",
                   help="the performer travels on a W x D m stage (docs/stage.md) and the real dancer as recorded "
                        "(not canonicalised, centred on the recorded span), the stage drawn on both floors and "
                        "the cameras following; default: both in place, facing +Z")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    a = p.parse_args(argv)
    if a.tempo is not None:
        try:
            a.tempo = tuple(float(v) for v in a.tempo.split(","))
        except ValueError:
            a.tempo = ()
        if len(a.tempo) != 2 or not all(0.25 <= r <= 4 for r in a.tempo):
            p.error("--tempo takes two rates in [0.25, 4] separated by a comma, e.g. 0.8,1.25")
    elif a.audio is not None:
        p.error("--audio works with --tempo only")
    if a.stage is not None:
        from models.errors import ConfigError
        from models.networks.stage import parse_stage

        if a.tempo is not None:
            p.error("--stage works without --tempo")
        try:
            a.stage = parse_stage(a.stage)
        except ConfigError as exc:
            p.error(f"--stage: {exc}")
    if not 0 < a.fps <= FPS:
        p.error(f"--fps must be in (0, {FPS}], got {a.fps}")
    if not a.seconds > 0:
        p.error(f"--seconds must be > 0, got {a.seconds}")
    try:
        w, h = (int(v) for v in a.size.lower().split("x"))
    except ValueError:
        p.error(f"--size must be WxH in pixels, got {a.size!r}")
    if not (64 <= w <= 1920 and 64 <= h <= 1080):
        p.error(f"--size must be between 64x64 and 1920x1080, got {a.size}")
    a.size = (w, h)
    if Path(a.out).suffix.lower() != ".gif":
        p.error(f"--out must be a .gif file, got {a.out}")
    return a


def load_tracks(a: argparse.Namespace) -> Tracks:
    """The real and generated poses of ``a.dance`` and the span to record."""
    import torch

    from models.data.dwm import STYLES, load_dance
    from models.data.split import split_names
    from models.evaluation.beats import music_beats
    from models.features.audio_io import load_audio
    from models.generate import load_model, run_model
    from models.generate import with_library
    from models.timebase import HOP, SAMPLE_RATE
    from models.data.corpus import build_corpus

    torch.set_num_threads(min(2, torch.get_num_threads()))
    loaded = with_library(load_model(a.checkpoint), a.library)
    (clip,) = build_corpus(a.data, [a.dance], loaded.features, (1.0,), a.cache, progress=False)
    start = int(round(a.start_s * FPS)) - 1 - clip.first_frame
    frames = int(round(a.seconds * FPS))
    lo, hi = (clip.first_frame + 1) / FPS, (clip.first_frame + clip.num_frames - frames) / FPS
    if not 0 <= start <= clip.num_frames - frames:
        raise PerformerError(f"{a.dance}: its motion capture covers song times {lo:.1f}-{hi + a.seconds:.1f} s; "
                             f"--start-s must be in {lo:.1f}..{hi:.1f} for --seconds {a.seconds:g}")
    song = load_audio(load_dance(Path(a.data) / a.dance).audio_path, SAMPLE_RATE)[0]
    # Models that hear the waveform (gcn) get the clip's audio: clip frame t ends at song sample (f0 + t + 1) * HOP.
    stage = a.stage if a.stage is not None else 0
    generated = run_model(loaded.model, clip.features, audio=song[clip.first_frame * HOP :], energy=a.energy,
                          stage=stage)
    real = clip.poses
    if a.stage is not None:  # the dancer as recorded: travel and heading kept, centred on the recorded span
        from models.data.corpus import clip_motion

        motion, _, f0, _ = clip_motion(load_dance(Path(a.data) / a.dance), len(clip.features) + clip.first_frame)
        real = motion.to_vector()[clip.first_frame - f0:][: len(clip.poses)].astype(np.float32)
        real[:, [0, 2]] -= real[start: start + frames, [0, 2]].mean(0)
    # Beats of a stretch a few seconds wider than the recording (the tracker needs context).
    f_lo = max(0, clip.first_frame + start - 5 * FPS)
    f_hi = clip.first_frame + start + frames + 5 * FPS
    beats = f_lo + music_beats(song[f_lo * HOP : f_hi * HOP])
    names = sorted(d.name for d in Path(a.data).iterdir() if d.is_dir() and d.name.startswith("DANCE_"))
    split = "validation" if a.dance in split_names(names)[1] else "training"
    label = (Path(a.library).name if a.library else loaded.path.name) + (f", energy {a.energy:g}" if a.energy != 1.0 else "")
    label += f", stage {a.stage[0]:g}x{a.stage[1]:g} m" if a.stage is not None else ""
    return Tracks(real, generated, start, frames, clip.first_frame, a.dance, STYLES[a.dance.split("_")[1]],
                  label, loaded.name, beats, split, stage=a.stage)


def load_tempo_tracks(a: argparse.Namespace) -> Tracks:
    """--tempo: the checkpoint's poses on the song stretched to each of ``a.tempo``'s rates, cut so
    that frame ``start`` of both is the moment ``a.start_s`` of the unstretched song."""
    import librosa
    import torch

    from models.data.dwm import STYLES, load_dance
    from models.evaluation.listening import heard_beats
    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model, run_model
    from models.generate import with_library
    from models.timebase import SAMPLE_RATE

    torch.set_num_threads(min(2, torch.get_num_threads()))
    loaded = with_library(load_model(a.checkpoint), a.library)
    path = Path(a.audio) if a.audio else load_dance(Path(a.data) / a.dance).audio_path
    song = load_audio(path, SAMPLE_RATE)[0]
    end_s = a.start_s + a.seconds * max(a.tempo) + 1.0
    if end_s * SAMPLE_RATE > len(song):
        raise PerformerError(f"{path}: {len(song) / SAMPLE_RATE:.1f} s long; --start-s {a.start_s:g} and --seconds "
                             f"{a.seconds:g} at {max(a.tempo):g}x need {end_s:.1f} s")
    src = song[: int(end_s * SAMPLE_RATE)]
    sides = []
    for r in a.tempo:
        y = src if r == 1.0 else librosa.effects.time_stretch(src, rate=r).astype(np.float32)
        poses = run_model(loaded.model, extract_features(y, loaded.features), energy=a.energy)
        sides.append((poses, heard_beats(y), int(round(a.start_s / r * FPS)) - 1))  # pose ending at song time start_s
    start = min(at for _, _, at in sides)
    frames = int(round(a.seconds * FPS))
    (pl, bl, al), (pr, br, ar) = sides
    name = a.dance if not a.audio else Path(a.audio).stem
    style = STYLES.get(a.dance.split("_")[1], "?") if not a.audio else "recording"
    label = (Path(a.library).name if a.library else loaded.path.name) + (f", energy {a.energy:g}" if a.energy != 1.0 else "")
    return Tracks(pl[al - start:], pr[ar - start:], start, frames, 0, name, style, label, loaded.name, np.array([]),
                  "tempo", a.tempo, (bl - (al - start), br - (ar - start)), a.start_s)


class Viewer:
    """One WebSocketSink and one viewer page in the browser, stepped frame by frame."""

    def __init__(self, browser, size: tuple[int, int]) -> None:
        from realtime.ws_server import WebSocketSink

        self.sink = WebSocketSink("127.0.0.1", 0)  # serves clients/web/dist, as performer run --ws
        self.page = browser.new_page(viewport={"width": size[0], "height": size[1]})
        self.errors: list[str] = []
        self.page.on("console", lambda m: m.type == "error" and self.errors.append(m.text))
        self.page.on("pageerror", lambda e: self.errors.append(f"uncaught: {e}"))
        self.page.goto(self.sink.url)
        self.page.add_style_tag(content=HIDE_HUD)
        self.sent = 0

    def wait_open(self, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while True:
            s = self.page.evaluate("window.performerStats")
            if s and s["state"] == "open" and s["bones"] > 0 and self.sink.stats()["clients"] == 1:
                if not s["webgl"]:
                    raise PerformerError("the viewer page has no WebGL in this chromium")
                return
            if time.monotonic() > deadline:
                raise PerformerError(f"viewer at {self.sink.url} never connected: {s}; errors {self.errors}")
            time.sleep(0.05)

    def send(self, pose: np.ndarray, song_time: float) -> None:
        from realtime.frame import PoseFrame

        i = self.sent
        self.sink.send(PoseFrame(i, (i + 1) * 735, song_time, time.monotonic(), np.asarray(pose, np.float32)))
        self.sent += 1

    def wait_drawn(self) -> None:
        """Until the page has received every frame sent and drawn the newest (two animation frames later)."""
        got = self.page.evaluate(
            """async (n) => {
                const until = performance.now() + 20000;
                while (!(window.performerStats && window.performerStats.framesReceived >= n)) {
                    if (performance.now() > until) break;
                    await new Promise((r) => setTimeout(r, 1));
                }
                await new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r)));
                return window.performerStats.framesReceived;
            }""",
            self.sent,
        )
        if got != self.sent:
            raise PerformerError(f"viewer received {got} frames of {self.sent} sent (reconnected or dropped)")

    def screenshot(self):
        from PIL import Image

        return Image.open(BytesIO(self.page.screenshot(type="png"))).convert("RGB")

    def frames_shown(self) -> int:
        """Stream frames the page applied to its avatar (published every 250 ms)."""
        time.sleep(0.4)
        return int(self.page.evaluate("window.performerStats.framesShown"))

    def close(self) -> None:
        self.page.close()
        self.sink.close()


def record(tracks: Tracks, size: tuple[int, int], fps: float, progress: bool = True) -> list:
    """Screenshots (left, right, clip frame) of the two viewers, ``fps`` per second."""
    from playwright.sync_api import sync_playwright

    preroll = min(TRAIL_FRAMES, tracks.start)
    first = tracks.start - preroll
    n_pictures = int(round(tracks.frames * fps / FPS))
    wanted = {tracks.start + int(round(j * FPS / fps)) for j in range(n_pictures)}
    shots = []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
        viewers: list[Viewer] = []
        try:
            viewers += [Viewer(browser, size), Viewer(browser, size)]
            for v in viewers:
                v.wait_open()
                if tracks.stage is not None:  # the rectangle on the floor; the cameras follow the dancers
                    v.sink.set_state({"stage": list(tracks.stage), "facing": "free"})
            t0 = time.monotonic()
            for t in range(first, tracks.start + tracks.frames):
                for v, poses in zip(viewers, (tracks.real, tracks.generated)):
                    v.send(poses[t], tracks.song_time(t))
                for v in viewers:
                    v.wait_drawn()
                if t in wanted:
                    shots.append((viewers[0].screenshot(), viewers[1].screenshot(), t))
                    if progress and len(shots) % 30 == 0:
                        print(f"  {len(shots)}/{n_pictures} pictures, {time.monotonic() - t0:.0f} s", file=sys.stderr)
            sent = tracks.start + tracks.frames - first
            for v in viewers:
                shown = v.frames_shown()
                if shown != sent:
                    raise PerformerError(f"a viewer applied {shown} of {sent} frames: stepping failed")
                if v.errors:
                    raise PerformerError(f"viewer page errors: {v.errors}")
        finally:
            for v in viewers:
                v.close()
            browser.close()
    return shots


def _font(size: int):
    from PIL import ImageFont

    for name in ("DejaVuSans.ttf", "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf"):
        try:
            return ImageFont.truetype(name, size)
        except OSError:
            pass
    return ImageFont.load_default(size)


def bands(size: tuple[int, int]) -> tuple[int, int, float]:
    """Heights (pixels) of the label band above the viewers and the song band below, and the text scale."""
    scale = max(0.6, min(1.5, size[0] / 480))
    return int(26 * scale), int(24 * scale), scale


def compose(tracks: Tracks, shots: list, size: tuple[int, int]) -> list:
    """Side-by-side pictures with a label band above and the song's time and beat below."""
    from PIL import Image, ImageDraw

    w, h = size
    top, bottom, scale = bands(size)
    big, small = _font(int(15 * scale)), _font(int(12 * scale))
    lit = set()
    for b in tracks.beats:
        lit.update(range(int(b), int(b) + max(1, int(round(BEAT_LIT_S * FPS)))))
    out = []
    for left, right, t in shots:
        img = Image.new("RGB", (2 * w, top + h + bottom), BG)
        img.paste(left, (0, top))
        img.paste(right, (w, top))
        d = ImageDraw.Draw(img)
        d.line([(w, 0), (w, top + h + bottom)], fill=LINE, width=2)
        pad = int(8 * scale)
        y = top + h + bottom // 2
        r = int(5 * scale)
        if tracks.rates is not None:  # --tempo: a label, song position and beat marker per side
            for k, (rate, beats) in enumerate(zip(tracks.rates, tracks.side_beats)):
                x0 = k * w
                d.text((x0 + pad, top // 2), f"song at {rate:g}x: {tracks.checkpoint}", fill=FG, font=big, anchor="lm")
                song_s = tracks.tempo_start_s + (t - tracks.start) / FPS * rate  # the unstretched song's time
                d.text((x0 + pad, y), f"{tracks.dance}   song time {song_s:6.2f} s", fill=DIM, font=small, anchor="lm")
                on = any(0 <= t - b < max(1, int(round(BEAT_LIT_S * FPS))) for b in beats)
                cx = x0 + w - pad - r
                d.ellipse([cx - r, y - r, cx + r, y + r], fill=BEAT if on else UNLIT)
                d.text((cx - r - pad // 2, y), "beat", fill=DIM, font=small, anchor="rm")
            out.append(img)
            continue
        d.text((pad, top // 2), "real dancer (motion capture)", fill=FG, font=big, anchor="lm")
        d.text((w + pad, top // 2), f"generated: {tracks.checkpoint}", fill=FG, font=big, anchor="lm")
        song_frame = tracks.first_song_frame + t
        d.text((pad, y), f"song: {tracks.dance} ({tracks.style}, {tracks.split} dance)   {tracks.song_time(t):6.2f} s",
               fill=DIM, font=small, anchor="lm")
        cx = 2 * w - pad - r
        d.ellipse([cx - r, y - r, cx + r, y + r], fill=BEAT if song_frame in lit else UNLIT)
        d.text((cx - r - pad // 2, y), "beat", fill=DIM, font=small, anchor="rm")
        out.append(img)
    return out


def write_gif(pictures: list, fps: float, out: Path) -> None:
    """One palette for the whole clip (no flicker), no dithering (small frame deltas)."""
    from PIL import Image

    k = min(8, len(pictures))
    sample = [pictures[int(i * (len(pictures) - 1) / max(1, k - 1))] for i in range(k)]
    w, h = sample[0].size
    sheet = Image.new("RGB", (w, h * k))
    for i, p in enumerate(sample):
        sheet.paste(p, (0, i * h))
    colours = sheet.quantize(colors=96, method=Image.Quantize.MEDIANCUT).getpalette()[: 3 * 96]
    for c in (BG, FG, DIM, BEAT, LINE, UNLIT):  # the overlay's own colours, exactly (the beat may be unlit in sample)
        colours += c
    palette = Image.new("P", (1, 1))
    palette.putpalette(colours)
    frames = [p.quantize(palette=palette, dither=Image.Dither.NONE) for p in pictures]
    # GIF delays are in 1/100 s: alternate them so the average is exactly 1/fps.
    ends = [int(round((j + 1) * 100 / fps)) for j in range(len(frames))]
    durations = [10 * (e - s) for s, e in zip([0, *ends[:-1]], ends)]
    out.parent.mkdir(parents=True, exist_ok=True)
    frames[0].save(out, save_all=True, append_images=frames[1:], duration=durations, loop=0, optimize=False)


def main(argv: list[str] | None = None) -> int:
    a = parse_args(argv)
    if not CHROMIUM.is_file():
        print(f"error: {CHROMIUM} not found (apt-get install chromium, or set PERFORMER_CHROMIUM)", file=sys.stderr)
        return 2
    try:
        import playwright  # noqa: F401
    except ImportError:
        print("error: the playwright Python package is missing (pip install -e '.[dev]')", file=sys.stderr)
        return 2
    try:
        say = (lambda *_: None) if a.quiet else (lambda *m: print(*m, file=sys.stderr))
        say(f"generating {a.audio or a.dance} with {a.checkpoint or 'the default checkpoint'}...")
        tracks = load_tempo_tracks(a) if a.tempo else load_tracks(a)
        at = a.start_s if a.tempo else tracks.song_time(tracks.start)
        say(f"recording {tracks.frames / FPS:g} s from song time {at:.2f} s "
            f"({tracks.model}, {tracks.checkpoint}) at {a.fps:g} pictures/s, {a.size[0]}x{a.size[1]} per side...")
        shots = record(tracks, a.size, a.fps, progress=not a.quiet)
        pictures = compose(tracks, shots, a.size)
        out = Path(a.out)
        write_gif(pictures, a.fps, out)
    except PerformerError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    w, h = pictures[0].size
    print(f"wrote {out}: {len(pictures)} pictures, {len(pictures) / a.fps:.2f} s at {a.fps:g}/s, {w}x{h}, "
          f"{out.stat().st_size / 1e6:.2f} MB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The lead, measured: does ``--lead`` put the motion back on the beat behind a display delay?

A display chain (renderer, projector, LED wall, stream encoder) shows the pose sent at
audio time t at t + D. With ``--lead D`` the performer sends the pose it takes at t + D,
so the audience sees it on time. For each validation dance of the DWM dataset and each
lead L (ms; L frames at 30 fps, ``round(L * 30 / 1000)``), the dancing checkpoint's live
stream (``dance_stream.generate(model, ..., lead=L)``: a fresh stream fed the song's frames, as
``performer run`` feeds them) is scored as the audience sees it behind a display of delay
L: its kinematic beats (``models.evaluation.beats.kinematic_beats``) shifted L frames
later, against the music beats ``performer evaluate`` scores with (``librosa.beat.beat_track``
on the song), beat hit rate within +-2 frames (``beat_hit_rate``, as benchmarks/studies/beat_warp.py).
Beside it: lead 0's motion behind the same delay (what the audience sees without the lead),
and each lead's ratio to lead 0's hit rate with no delay (issue 25, target 5: at least 0.9)::

    .venv/bin/python benchmarks/studies/lead.py --data ../shared/data/dwm

``--music DIR`` scores every recording of DIR instead (issue 43: the lead on any song), each
up to the end of its music (``models.evaluation.listening.music_end``: trailing silence,
brahms' applause), against ``librosa.beat.beat_track`` on the recording; ``--max-s`` cuts
each to its first seconds. ``--spread`` adds, per song, 95 % bootstrap intervals of the last
lead's ratio over the seeds and over the song's 5-s blocks (is a shortfall the draw, or the
few beats of one song?); ``--oracle`` dances the leads with the tracker's true phase of the
lead's frame (the ceiling of any forecast; ``--oracle-changes`` only where the tracker's
level changes within the lead); ``--rotation`` with the forecast the lead read
before issue 43 (the phase rotated by ``2 pi L / P``), ``--period-only`` with the onset forecast
before the runner-up period (``models.networks.lead.RUNNER_UP``), ``--runner-up-change OCT`` with
the runner-up's level taken where it lies at least OCT octave off (``RUNNER_UP_CHANGE``; 0: at any
change of level); ``--levels`` counts, dancing
nothing, how the forecast reads the tracker's changes of level (:func:`level_changes`).

Each song is danced with seeds 0 to 5 (``--seeds``, as benchmarks/listening.py) at every lead. Hit rates are pooled
over songs and seeds (every kinematic beat counts once), with the smallest and largest song
in brackets. Exit status 2 on a missing or unreadable
checkpoint or dataset, or a checkpoint whose model has no lead control.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

#: Leads measured by default, ms (0 = none; 67 and 133 ms are 2 and 4 frames at 30 fps).
LEADS_MS: tuple[float, ...] = (0.0, 67.0, 133.0)
#: Blocks of a recording (s) that ``--spread`` redraws to tell how much a ratio owes to the
#: recording's few beats rather than to the lead.
BLOCK_S: float = 5.0


def lead_frames(lead_ms: float) -> int:
    """Frames (30 fps) of a lead of ``lead_ms`` ms, as the stream rounds it."""
    from models.timebase import FPS

    return int(round(lead_ms * FPS / 1000.0))


def seen_hits(kin: np.ndarray, mus: np.ndarray, delay: int) -> tuple[int, int]:
    """(kinematic beats within +-2 frames of a music beat, kinematic beats) of motion with beats at
    frames ``kin`` shown ``delay`` frames late."""
    from models.evaluation.beats import beat_hit_rate

    return int(round(beat_hit_rate(kin + delay, mus) * len(kin))), len(kin)


def block_hits(kin: np.ndarray, mus: np.ndarray, blocks: int) -> np.ndarray:
    """(blocks, 2) int: per :data:`BLOCK_S` block of the recording, (kinematic beats at frames ``kin``
    within +-2 frames of a music beat, kinematic beats), each beat counted in the block it falls in."""
    from models.evaluation.beats import BEAT_TOLERANCE

    kin = np.asarray(kin, np.int64)
    out = np.zeros((blocks, 2), np.int64)
    if len(kin) == 0 or len(mus) == 0:
        return out
    hit = np.min(np.abs(kin[:, None] - np.asarray(mus)[None, :]), axis=1) <= BEAT_TOLERANCE
    b = np.clip(kin // int(round(BLOCK_S * 30)), 0, blocks - 1)
    np.add.at(out[:, 0], b, hit.astype(np.int64))
    np.add.at(out[:, 1], b, 1)
    return out


def spread(detail: dict[str, list[np.ndarray]], lead_ms: float, draws: int = 4000) -> dict[str, float]:
    """The ratio at ``lead_ms`` (the lead's motion behind its delay over lead 0's, no delay) of one
    recording from :func:`measure_song`'s ``detail``, and its 95 % bootstrap intervals: over the
    seeds (both leads' seeds redrawn) and over the recording's :data:`BLOCK_S` blocks (the same
    blocks for both, all seeds): ``{"ratio", "seeds_lo", "seeds_hi", "blocks_lo", "blocks_hi"}``."""
    a, b = np.stack(detail[f"{lead_ms:g}"]), np.stack(detail["0"])  # (seeds, blocks, 2)
    rng = np.random.default_rng(0)

    def ratio(x: np.ndarray, y: np.ndarray) -> float:
        return (x[..., 0].sum() / max(x[..., 1].sum(), 1)) / max(y[..., 0].sum() / max(y[..., 1].sum(), 1), 1e-9)

    n, k = a.shape[:2]
    by_seed = [ratio(a[rng.integers(0, n, n)], b[rng.integers(0, n, n)]) for _ in range(draws)]
    by_block = [ratio(a[:, i], b[:, i]) for i in (rng.integers(0, k, k) for _ in range(draws))]
    (slo, shi), (blo, bhi) = np.percentile(by_seed, [2.5, 97.5]), np.percentile(by_block, [2.5, 97.5])
    return {"ratio": ratio(a, b), "seeds_lo": slo, "seeds_hi": shi, "blocks_lo": blo, "blocks_hi": bhi}


def oracle_generate(model, features: np.ndarray, seed: int = 0, lead: float = 0.0,
                    changes: bool = False) -> np.ndarray:
    """``dance_stream.generate`` with the lead's beat phase read from the features ``lead`` frames
    on (the tracker's true phase there, its clarity as now): what no causal forecast can beat.
    ``changes``: only at the frames whose next ``lead`` frames change the tracker's period by more
    than 0.1 octave (a change of level), the stream's own forecast elsewhere."""
    import math

    from models.networks.dance_stream import DanceStream

    class Oracle(DanceStream):
        def _ahead(self, row: np.ndarray) -> np.ndarray:
            ccos, csin, _, logp = self._beat_cols
            j = min(self.frame + self._lead, len(features) - 1)
            if changes and abs(float(features[j, logp]) - float(row[logp])) <= 0.1:
                return super()._ahead(row)
            a, r = math.atan2(features[j, csin], features[j, ccos]), math.hypot(row[ccos], row[csin])
            out = row.copy()
            out[ccos], out[csin] = r * math.cos(a), r * math.sin(a)
            return out

    return Oracle(model, seed=seed, lead_ms=lead).push(features)


def measure_song(model, features: np.ndarray, mus: np.ndarray, leads: Sequence[float],
                 seeds: Sequence[int] = (0,), detail: dict | None = None,
                 oracle: bool | str = False) -> dict[str, dict[str, list[int]]]:
    """``{str(lead_ms): {"seen": [hits, beats], "no_lead": [hits, beats], "undelayed": [hits, beats]},
    "chance": hit rate of beats at random frames}`` for one song, counts summed over ``seeds``: ``seen`` the lead's motion behind a display delay of
    the lead, ``no_lead`` lead 0's motion behind the same delay, ``undelayed`` the lead's
    motion with no delay. ``leads[0]`` must be 0. ``detail``, if given, gets per lead (``str(ms)``)
    one :func:`block_hits` array a seed of the lead's motion behind its delay (for :func:`spread`).
    ``oracle``: the leads danced with :func:`oracle_generate` instead (``"changes"``: its
    ``changes=True``)."""
    from models.evaluation.beats import kinematic_beats
    from models.evaluation.evaluate import positions
    from models.networks.dance_stream import generate as stream_generate

    from models.evaluation.beats import chance_hit_rate

    out: dict = {f"{ms:g}": {"seen": [0, 0], "no_lead": [0, 0], "undelayed": [0, 0]} for ms in leads}
    out["chance"] = chance_hit_rate(mus, len(features))
    for seed in seeds:
        gen = (lambda *a, **k: oracle_generate(*a, **k, changes=oracle == "changes")) if oracle else stream_generate
        kins = {ms: kinematic_beats(positions(gen(model, features, seed=seed, lead=ms))) for ms in leads}
        for ms in leads:
            d, row = lead_frames(ms), out[f"{ms:g}"]
            for key, kin, delay in (("seen", kins[ms], d), ("no_lead", kins[leads[0]], d), ("undelayed", kins[ms], 0)):
                row[key] = [a + b for a, b in zip(row[key], seen_hits(kin, mus, delay))]
            if detail is not None:
                blocks = max(1, -(-len(features) // int(round(BLOCK_S * 30))))
                detail.setdefault(f"{ms:g}", []).append(block_hits(kins[ms] + d, mus, blocks))
    return out


def level_changes(model, features: np.ndarray, lead: int) -> dict[str, dict[str, float]]:
    """How the lead's forecast (``PhaseForecast.ahead``) reads the beat tracker's changes of level
    on one recording's features (T, D), ``lead`` frames on, with ``RUNNER_UP`` on and off:
    ``{"on"|"off": {"frames", "changes", "caught", "wrong", "miss"}}``: of the frames after the
    tracker's first window (6 s), those whose next ``lead`` frames change its period by more than
    0.1 octave, how many of them the forecast's period matches the period ``lead`` frames on
    (within 0.1 octave), at how many others it forecasts a period that is neither, and the mean
    miss of its phase (frames of the period ``lead`` frames on)."""
    import math

    from models.features.context import TEMPO_WINDOW
    from models.networks import lead as lead_part

    on, cc = features[:, model.config.onset_col], model.config.clarity_col
    period = 15.0 * 2.0 ** features[:, cc + 1].astype(np.float64)
    theta = np.arctan2(features[:, cc - 1], features[:, cc - 2]).astype(np.float64)
    octave = lambda a, b: abs(math.log2(a / b)) > 0.1  # noqa: E731
    out, shipped = {}, lead_part.RUNNER_UP
    try:
        for key, runner_up in (("on", True), ("off", False)):
            lead_part.RUNNER_UP = runner_up
            f, row, miss = lead_part.PhaseForecast(), dict.fromkeys(("frames", "changes", "caught", "wrong"), 0), []
            for t in range(len(features) - lead):
                f.push(float(on[t]))
                if t < TEMPO_WINDOW:
                    continue
                a, logp = f.ahead(lead, float(period[t]))
                p = period[t] if logp is None else 15.0 * 2.0 ** logp
                change, right = octave(period[t + lead], period[t]), not octave(p, period[t + lead])
                row["frames"] += 1
                row["changes"] += change
                row["caught"] += change and right
                row["wrong"] += octave(p, period[t]) and not right
                miss.append(abs(math.remainder(a - theta[t + lead], 2 * math.pi)) / (2 * math.pi) * period[t + lead])
            out[key] = {**row, "miss": float(np.mean(miss)) if miss else 0.0}
    finally:
        lead_part.RUNNER_UP = shipped
    return out


def table(results: dict[str, dict], leads: Sequence[float]) -> str:
    """Markdown: per lead, pooled hit rates [smallest, largest song] and the ratio to lead 0's."""
    def rate(ms: float, key: str) -> tuple[float, float, float]:
        rows = [r[f"{ms:g}"][key] for r in results.values()]
        per = [h / max(n, 1) for h, n in rows]
        return sum(h for h, _ in rows) / max(sum(n for _, n in rows), 1), min(per), max(per)

    ref = rate(0.0, "undelayed")[0]
    lines = ["| lead (ms) | frames | hit rate seen behind a display delay of the lead | "
             "ratio to lead 0 (no delay) | lead 0's motion behind the same delay | the lead's motion, no delay |",
             "| ---: | ---: | ---: | ---: | ---: | ---: |"]
    for ms in leads:
        seen, nolead, undelayed = rate(ms, "seen"), rate(ms, "no_lead"), rate(ms, "undelayed")
        cell = lambda r: f"{r[0]:.3f} [{r[1]:.2f}, {r[2]:.2f}]"  # noqa: E731
        lines.append(f"| {ms:g} | {lead_frames(ms)} | {cell(seen)} | {seen[0] / max(ref, 1e-9):.2f} | "
                     f"{cell(nolead)} | {cell(undelayed)} |")
    return "\n".join(lines)


def song_table(results: dict[str, dict], leads: Sequence[float]) -> str:
    """Markdown: per song, lead 0's hit rate, and per other lead the ratio to it of the lead's
    motion behind its delay and of lead 0's motion behind the same delay."""
    rest = [ms for ms in leads if ms != 0]
    head = "| song | lead 0 hit rate | " + " | ".join(f"{ms:g} ms: with the lead / without" for ms in rest) + " |"
    lines = [head, "| --- | ---: |" + " ---: |" * len(rest)]
    for song, row in results.items():
        ref = row["0"]["undelayed"][0] / max(row["0"]["undelayed"][1], 1)
        cells = []
        for ms in rest:
            seen, nolead = (row[f"{ms:g}"][k][0] / max(row[f"{ms:g}"][k][1], 1) for k in ("seen", "no_lead"))
            cells.append(f"{seen / max(ref, 1e-9):.2f} / {nolead / max(ref, 1e-9):.2f}")
        lines.append(f"| {song} | {ref:.3f} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def run(checkpoint: str, data_root: str | Path, cache_dir: str | Path | None, leads: Sequence[float],
        seeds: Sequence[int] = (0,), songs: Sequence[str] | None = None, log=print,
        details: dict | None = None, levels: bool = False) -> dict[str, dict]:
    """Load, generate and score every validation dance (see the module docstring); ``{song: measure_song(...)}``
    (``details``, if given: ``{song: measure_song's detail}``; ``levels``: ``{song: level_changes(...)}``
    at the last lead instead, nothing danced)."""
    import torch

    from models.errors import ConfigError
    from models.evaluation.evaluate import EvalOptions, clip_music_beats, load_clips, validation_names
    from models.generate import load_model
    from models.networks.dance_vq import DanceVQ

    lm = load_model(checkpoint)
    if not isinstance(lm.model, DanceVQ):
        raise ConfigError(f"{checkpoint}: model {type(lm.model).__name__} has no lead control (dance_vq models do)")
    opts = EvalOptions(cache_dir=cache_dir, progress=False)
    names = validation_names(data_root, songs, opts)
    out: dict[str, dict] = {}
    with torch.no_grad():
        for i, c in enumerate(load_clips(data_root, names, lm.features, opts), 1):
            if levels:
                out[c.name] = level_changes(lm.model, c.features, lead_frames(leads[-1]))
                continue
            log(f"  [{i}/{len(names)}] {c.name}: lead {', '.join(f'{x:g}' for x in leads)} ms")
            out[c.name] = measure_song(lm.model, c.features, clip_music_beats(data_root, c), leads, seeds,
                                       None if details is None else details.setdefault(c.name, {}))
    return out


def run_music(checkpoint: str, music_dir: str | Path, leads: Sequence[float], seeds: Sequence[int] = (0,),
              songs: Sequence[str] | None = None, max_s: float | None = None, log=print,
              details: dict | None = None, oracle: bool | str = False, levels: bool = False) -> dict[str, dict]:
    """:func:`run` on every recording of ``music_dir`` (or those whose stem is in ``songs``): the
    features of the recording up to the end of its music (at most ``max_s`` seconds), its beats
    by ``librosa.beat.beat_track`` on the same span; ``{stem: measure_song(...)}`` (``levels``:
    ``{stem: level_changes(...)}`` at the last lead instead, nothing danced)."""
    import torch

    from models.errors import ConfigError
    from models.evaluation.beats import music_beats
    from models.evaluation.listening import HOP, SAMPLE_RATE, AudioCache, music_end, music_files
    from models.features.spectral import extract_features
    from models.generate import load_model
    from models.networks.dance_vq import DanceVQ
    from models.timebase import FPS

    lm = load_model(checkpoint)
    if not isinstance(lm.model, DanceVQ):
        raise ConfigError(f"{checkpoint}: model {type(lm.model).__name__} has no lead control (dance_vq models do)")
    files = [f for f in music_files(music_dir) if not songs or f.stem in songs]
    cache = AudioCache(None)
    out: dict[str, dict] = {}
    with torch.no_grad():
        for i, f in enumerate(files, 1):
            audio = cache.audio(f)
            feats = extract_features(audio, lm.features)
            end = music_end(lm, feats, f.stem)[1]
            if max_s is not None:
                end = min(end, int(round(max_s * FPS)))
            feats = feats[:end]
            if levels:
                out[f.stem] = level_changes(lm.model, feats, lead_frames(leads[-1]))
                continue
            mus = music_beats(audio[: end * HOP], SAMPLE_RATE, FPS)  # frame t ends at sample (t + 1) HOP
            log(f"  [{i}/{len(files)}] {f.stem} ({end / FPS:.0f} s): lead {', '.join(f'{x:g}' for x in leads)} ms")
            out[f.stem] = measure_song(lm.model, feats, mus[mus < end], leads, seeds,
                                       None if details is None else details.setdefault(f.stem, {}), oracle)
    return out


def main(argv: list[str] | None = None) -> int:
    from models.evaluation.listening import SEEDS

    p = argparse.ArgumentParser(description=__doc__.split("\nHit rates")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="Exit status 2 on a missing or unreadable checkpoint or dataset, "
                                       "or a checkpoint whose model has no lead control.")
    p.add_argument("--checkpoint", default="models/assets/default.pt", metavar="CKPT",
                   help="a dance_vq checkpoint (default: models/assets/default.pt)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--data", metavar="DIR",
                     help="the DWM dataset directory (holds DANCE_* dirs): its validation dances")
    src.add_argument("--music", metavar="DIR", help="a directory of recordings (.ogg, .wav, .flac, .mp3): each of them")
    p.add_argument("--max-s", type=float, metavar="S", help="with --music: each recording's first S seconds at most")
    p.add_argument("--cache", default=".cache/corpus", metavar="DIR", help="corpus cache (default .cache/corpus)")
    p.add_argument("--leads", type=float, nargs="+", default=list(LEADS_MS), metavar="MS",
                   help=f"leads, ms, each in [0, 200], the first 0 (default {' '.join(f'{x:g}' for x in LEADS_MS)})")
    p.add_argument("--songs", nargs="+", metavar="NAME",
                   help="only these validation dances or recordings (stems; default: all)")
    p.add_argument("--seeds", type=int, nargs="+", default=list(SEEDS), metavar="N",
                   help="generation seeds, each run at every lead, counts summed "
                        f"(default {' '.join(map(str, SEEDS))}, as benchmarks/listening.py)")
    p.add_argument("--spread", action="store_true",
                   help=f"also print each song's ratio at the last lead with 95 %% bootstrap intervals over the "
                        f"seeds and over its {BLOCK_S:g}-s blocks (how much of it is the draw, how much the song)")
    for flag, what in (  # how the leads are danced or read, instead of the shipped forecast
            ("--oracle", "with --music: dance each lead with the tracker's true phase of the lead's frame (read from "
                         "the recording's future, the ceiling of any forecast) instead of the stream's forecast"),
            ("--oracle-changes", "with --music: as --oracle, but only at the frames whose next lead frames change the "
                                 "tracker's level (period by more than 0.1 octave), the stream's forecast elsewhere"),
            ("--rotation", "the lead's phase as the tracker's of now rotated by 2 pi L / P (the forecast before issue 43; "
                           "models.networks.lead.ONSET_FORECAST off) instead of its forecast from the onsets"),
            ("--period-only", "the forecast taking the onsets not heard yet as those one tracker period back only, its "
                              "period as now (before issue 43's runner-up; models.networks.lead.RUNNER_UP off)"),

            ("--levels", "instead of dancing, count per recording the frames whose next lead frames (the "
                         "last of --leads) change the beat tracker's level, how many of them the forecast catches and "
                         "at how many others it forecasts a wrong level, with the runner-up and without")):
        p.add_argument(flag, action="store_true", help=what)
    p.add_argument("--runner-up-change", type=float, metavar="OCT",
                   help="take the runner-up's level where it lies at least OCT octave from the tracker's (default "
                        "models.networks.lead.RUNNER_UP_CHANGE; 0: at any change of level, the forecast before it)")
    p.add_argument("--json", metavar="OUT", help="also write every song's counts as JSON")
    a = p.parse_args(argv)
    for flag, on in (("--oracle", a.oracle), ("--oracle-changes", a.oracle_changes)):
        if on and not a.music:
            p.error(f"{flag} needs --music")
    if any(not 0.0 <= x <= 200.0 for x in a.leads) or a.leads[0] != 0.0:
        p.error("--leads must each be in [0, 200] ms, the first 0 (the reference)")
    import torch

    from models.errors import PerformerError

    torch.set_num_threads(1)
    if a.runner_up_change is not None and not 0.0 <= a.runner_up_change <= 5.0:
        p.error(f"--runner-up-change must be in [0, 5] octaves, got {a.runner_up_change:g}")
    if a.rotation or a.period_only or a.runner_up_change is not None:
        from models.networks import lead as lead_part

        lead_part.ONSET_FORECAST = not a.rotation
        lead_part.RUNNER_UP = not a.period_only
        if a.runner_up_change is not None:
            lead_part.RUNNER_UP_CHANGE = a.runner_up_change
    try:
        log = lambda m: print(m, file=sys.stderr)  # noqa: E731
        details: dict | None = {} if a.spread else None
        results = (run_music(a.checkpoint, a.music, a.leads, a.seeds, a.songs, a.max_s, log=log, details=details,
                             oracle="changes" if a.oracle_changes else a.oracle, levels=a.levels)
                   if a.music else run(a.checkpoint, a.data, a.cache, a.leads, a.seeds, a.songs, log=log,
                                       details=details, levels=a.levels))
    except (PerformerError, OSError) as e:
        print(f"lead.py: {e}", file=sys.stderr)
        return 2
    if a.levels:
        print(f"The beat tracker's level changes within a {a.leads[-1]:g}-ms lead, frames after its first 6 s "
              "(caught: the forecast's period is the one the tracker reads a lead on; wrong: a level it does not "
              "read; miss: the forecast's mean phase miss, frames), with the runner-up / the period only\n")
        print("| recording | frames | level changes | caught | wrong | miss |\n| --- | ---: | ---: | ---: | ---: | ---: |")
        for song, r in results.items():
            on, off = r["on"], r["off"]
            print(f"| {song} | {on['frames']} | {on['changes']} | {on['caught']} / {off['caught']} | "
                  f"{on['wrong']} / {off['wrong']} | {on['miss']:.2f} / {off['miss']:.2f} |")
        return 0
    what = f"recordings of {a.music}" if a.music else "validation dances"
    print(f"The lead on {len(results)} {what} ({a.checkpoint}, seeds {' '.join(map(str, a.seeds))}): "
          "beat hit rate (+-2 frames), pooled over songs and seeds [smallest, largest song]\n")
    print(table(results, a.leads))
    chance = np.mean([row["chance"] for row in results.values()])
    print(f"\n(Kinematic beats at random frames would hit {chance:.3f} of the time: the mean over the songs of "
          "models.evaluation.beats.chance_hit_rate.)")
    print("\nPer song: ratio to the song's lead 0 hit rate (no delay) of what the audience sees behind a "
          "display delay of the lead, with the lead / without it\n")
    print(song_table(results, a.leads))
    if details:
        print(f"\nPer song at {a.leads[-1]:g} ms: the ratio, and its 95 % bootstrap interval over the seeds / over "
              f"the song's {BLOCK_S:g}-s blocks\n")
        for song, d in details.items():
            r = spread(d, a.leads[-1])
            print(f"{song}: {r['ratio']:.2f} [{r['seeds_lo']:.2f}, {r['seeds_hi']:.2f}] / "
                  f"[{r['blocks_lo']:.2f}, {r['blocks_hi']:.2f}]")
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps(results, indent=1))
        print(f"\nwrote {a.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""A user's motion library danced to music (issue 40, items 2-3): is the played motion the user's,
does it listen, does ``--style`` pick the folder? The shipped default beside it, same run.

The library (``performer library build``, docs/library.md) plays through the default's
predictor (models/networks/library_player.py), or with ``--chooser match`` through issue 40's
second design (models/networks/motion_match.py: music descriptors pick windows by descriptor). On every recording of ``--music`` (an excerpt
from ``--start`` s of ``--seconds`` s) the library performer and the default dance (seed 0,
in place); from 3 s on, every frame it dances (idle weight 0) is put in the body's own frame
(root at the origin, the heading of the line between the upper legs removed) and compared with

* the library's clips (the user's frames, in the same body frame) and
* the DWM dances of ``--dwm`` (all 40; those the library holds as BVH, by name, left out),

reporting the share of frames nearer the user's than the DWM's and the median RMS joint
distance (over the 30 points) to the nearest user frame; the default's baseline: its share
nearer the library's clips, and its median distance to the nearest DWM frame. Then:

* continuation: the share of code steps (dancing) whose exemplar continues the playing one (same
  clip, about 8 frames on): how often the player can play the user's dance on as recorded;
* bends: at every code step, how far the handover bent the motion (degrees a bone: the played
  exemplar's own first pose against the motion's), median and largest per recording;
* seams: the handover seam ratio (benchmarks/studies/seams.py's measure for dance_vq: angular
  acceleration within 1 frame of frame ``8k + 2`` over the rest), per recording;
* listening (models/evaluation/listening.py, as benchmarks/listening.py for the default): the
  stretch set of ``--music`` (recordings of 80-130 bpm, 0.8x/1.0x/1.25x, ``--seeds``): speed
  ratio 1.25x over 0.8x (the mean over the seeds, and each seed's own: the worst must pass too), beat hit rate at 1.0x and its half-shifted control; the idle share of
  every recording up to the end of its music (presence set);
* folders: under ``auto``, each folder's share of the dancing frames (by the playing exemplar's
  folder) and the folder changes a minute of dancing, with the music's folder choice
  (models/networks/library_folders.py) off and on, the two interleaved recording by recording,
  with each one's seam ratio;
* style: with each folder of the library requested, the share of dancing frames whose playing
  exemplar is that folder's (``DanceStream.playing_member``), and (after the slash) the share
  nearer that folder's clips than the other folders' (the handover's bend counts against it).

Targets (issue 40): >= 90 % nearer, median <= 6.2 cm, seam ratio <= 1.2, speed ratio >= 1.40,
hit >= 0.40 and >= 1.5x the control, idle <= 2 %, style >= 90 %. Prints a table and PASS/FAIL,
writes OUT/library_play.json::

    .venv/bin/performer library build ../shared/data/motion /tmp/ballroom --out /tmp/lib.npz
    nice -n 5 .venv/bin/python benchmarks/studies/library_play.py --library /tmp/lib.npz

(/tmp/ballroom: DWM dances written as BVH, ``--write-dwm /tmp/ballroom DANCE_C_2 ...`` does
it). The DWM frames are cached under ``--cache``. Exit status 2 on a missing input.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

SETTLE = 90  # frames (3 s) before anything is scored
TARGETS = (("nearer_user", ">=", 0.90), ("median_cm", "<=", 6.2), ("seam", "<=", 1.2), ("speed_ratio", ">=", 1.40),
           ("speed_ratio_seed_min", ">=", 1.40),
           ("hit", ">=", 0.40), ("hit_over_control", ">=", 1.5), ("idle_max", "<=", 0.02), ("style_min", ">=", 0.90))


def body_frame(poses: np.ndarray) -> np.ndarray:
    """(T, 30, 3) FK points (m) of poses (T, P) with the root at the origin and the heading of the
    left-to-right upper-leg line removed (that line along +X)."""
    from models.evaluation.evaluate import positions
    from models.rig.humanoid import BONE_INDEX

    pos = positions(poses)
    pos = pos - pos[:, :1]
    hips = pos[:, BONE_INDEX["RightUpperLeg"]] - pos[:, BONE_INDEX["LeftUpperLeg"]]
    ang = np.arctan2(hips[:, 2], hips[:, 0])
    c, s = np.cos(ang)[:, None], np.sin(ang)[:, None]
    x, z = pos[..., 0], pos[..., 2]
    return np.stack([c * x + s * z, pos[..., 1], -s * x + c * z], -1)


class Nearest:
    """Nearest reference frame (RMS over the points, m) of body-frame points (n, 30, 3)."""

    def __init__(self, frames: np.ndarray) -> None:
        from scipy.spatial import cKDTree

        self.j = frames.shape[1]
        self.tree = cKDTree(frames.reshape(len(frames), -1))

    def __call__(self, frames: np.ndarray) -> np.ndarray:
        d, _ = self.tree.query(frames.reshape(len(frames), -1), workers=1)
        return d / np.sqrt(self.j)


def dwm_frames(root: Path, cache: Path, skip: set[str]) -> np.ndarray:
    """Body-frame points of every DWM dance under ``root`` but those in ``skip``, cached per dance."""
    from models.data.corpus import clip_motion
    from models.data.dwm import dance_dirs, load_dance
    from models.data.library import clip_tracks

    cache.mkdir(parents=True, exist_ok=True)
    out = []
    for d in dance_dirs(root):
        if d.name in skip:
            continue
        f = cache / f"{d.name}.npy"
        if not f.is_file():
            motion = clip_motion(load_dance(d), 10**7, 1.0)[0]
            np.save(f, body_frame(clip_tracks(motion)[0])[::2].astype(np.float32))  # every other frame
        out.append(np.load(f))
    return np.concatenate(out)


def member_windows(model, poses: list[np.ndarray]) -> np.ndarray:
    """(K, M, 2) int64: the (clip, start frame) of every exemplar window of a library model, found by
    its first two frames among ``poses`` (the clips as library_model got them); (-1, -1) for none."""
    import torch

    from models.networks.library_player import WINDOW_STRIDE

    key = lambda a: torch.from_numpy(np.ascontiguousarray(a, np.float32)).half().numpy().tobytes()  # noqa: E731
    where = {key(p[a: a + 2]): (c, a) for c, p in enumerate(poses) for a in range(0, len(p) - 1, WINDOW_STRIDE)}
    mp, n = model.member_poses, model.member_count.numpy()
    out = np.full(mp.shape[:2] + (2,), -1, np.int64)
    for k in range(mp.shape[0]):
        for j in range(int(n[k])):
            out[k, j] = where.get(mp[k, j, :2].numpy().tobytes(), (-1, -1))
    return out


def perform(model, feats: np.ndarray, style: str | None = None, windows: np.ndarray | None = None,
            bends: list | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(poses (T, P), dancing (T,) bool: idle weight 0 and past :data:`SETTLE`, the style token of
    the exemplar playing (T,): ``member_style``, library folder i = 4 + i, and the share of code
    steps whose exemplar is the playing one's own continuation: the same clip, starting within
    ``seg / 2`` frames of ``seg`` frames on; ``windows`` from :func:`member_windows`; NaN without)
    of one stream, seed 0, in place. ``bends`` receives, at every code step while dancing, how far
    the handover bent the motion: the mean over the bones of the rotation (degrees) between the
    played exemplar's own first pose and the motion's (library_player.bend_deg)."""
    from models.networks.library_player import bend_deg
    from models.networks.dance_stream import DanceStream

    s = DanceStream(model, seed=0, style=style)
    poses = np.empty((len(feats), model.config.pose_dim), np.float32)
    dance = np.zeros(len(feats), bool)
    token = np.zeros(len(feats), np.int64)
    styles = model.member_style.numpy()
    steps, cont, prev, seg = 0, 0, None, model.config.seg
    for t in range(len(feats)):
        n = s._handover.handovers  # a new exemplar played (models/networks/handover.py)
        poses[t] = s.push(feats[t: t + 1])[0]
        dance[t] = s.idle_weight == 0.0 and t >= SETTLE
        token[t] = styles[s.playing_member] if s.playing_member is not None else -1
        if bends is not None and s._handover.handovers != n and s.playing_member is not None and dance[t]:
            bends.append(bend_deg(s._chooser.members[s.playing_member][0], s._player._played[s._handover.start]))
        if windows is not None and s._handover.handovers != n and s.playing_member is not None:
            w = windows[s.playing_member]
            if prev is not None and dance[t]:
                steps += 1
                cont += int(w[0] >= 0 and w[0] == prev[0] and abs(w[1] - prev[1] - seg) <= seg // 2)
            prev = w
    return poses, dance, token, (cont / steps if steps else float("nan"))


def folder_shares(model, feats: np.ndarray) -> dict:
    """Under auto, with the folder choice (library_folders.FOLDER_CHOICE) off, then on: the dancing
    frames' folder tokens' counts, the folder changes among consecutive dancing frames, the dancing
    frames and the seam ratio, one stream each (seed 0)."""
    import models.networks.library_folders as lf

    out, was = {}, lf.FOLDER_CHOICE
    try:
        for key, on in (("off", False), ("on", True)):
            lf.FOLDER_CHOICE = on
            poses, dance, token, _ = perform(model, feats)
            tok = token[dance]
            lib = tok[tok >= 4]
            out[key] = {"frames": int(dance.sum()), "tokens": {int(t): int((tok == t).sum()) for t in np.unique(tok)},
                        "changes": int(np.sum(lib[1:] != lib[:-1])), "seam": handover_seam(model, poses)}
    finally:
        lf.FOLDER_CHOICE = was
    return out


def summarize_folders(rows: list[dict], names) -> dict:
    """Each folder's share of all dancing frames, the folder changes a minute of dancing (30 fps),
    the worst seam, off and on (:func:`folder_shares` of every recording); printed."""
    from models.networks.library_player import STYLE_BASE

    out = {}
    for key in ("off", "on"):
        n = sum(r[key]["frames"] for r in rows)
        share = {f: sum(r[key]["tokens"].get(STYLE_BASE + i, 0) for r in rows) / max(n, 1) for i, f in enumerate(names)}
        per_min = sum(r[key]["changes"] for r in rows) / max(n / 1800.0, 1e-9)
        rec = [min(r[key]["tokens"].get(STYLE_BASE + i, 0) / max(r[key]["frames"], 1) for i in range(len(names)))
               for r in rows]
        out[key] = {"share": share, "changes_per_min": per_min, "seam": max(r[key]["seam"] for r in rows),
                    "recordings_with_both": int(sum(v > 0 for v in rec))}
        print(f"auto, folder choice {key}: dancing frames by folder " + ", ".join(f"{f} {v:.3f}" for f, v in share.items())
              + f"; {per_min:.2f} folder changes a minute; {out[key]['recordings_with_both']} of {len(rows)} "
              f"recordings play every folder; worst seam {out[key]['seam']:.2f}")
    return out


def handover_seam(model, poses: np.ndarray) -> float:
    from models.networks.blend import seam_ratio
    from models.networks.player import WARP_LAG

    seg = model.config.seg
    return seam_ratio(poses[int(round(WARP_LAG)) % seg:], seg, seg, radius=1)


def write_dwm(out: Path, names: list[str], dwm: Path) -> None:
    """Write DWM dances as BVH (the rig's skeleton, cm, root travel and turns kept) into ``out``."""
    from models.data.alignment import resample_positions
    from models.data.dwm import load_dance
    from models.rig.bvh import write_bvh
    from models.rig.retarget import retarget
    from models.rig.skeleton import load_default_skeleton

    out.mkdir(parents=True, exist_ok=True)
    for n in names:
        a = resample_positions(load_dance(dwm / n))
        write_bvh(out / f"{n}.bvh", retarget(a.positions_m, load_default_skeleton(), source=n), load_default_skeleton())
        print(f"wrote {out / n}.bvh")


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--library", type=Path, metavar="FILE.npz", help="the library to dance (performer library build)")
    p.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data", metavar="DIR",
                   help="shared data: DIR/dwm (the DWM dances), DIR/music (the recordings); default ../shared/data")
    p.add_argument("--start", type=float, default=10.0, help="excerpt start, s (default 10)")
    p.add_argument("--seconds", type=float, default=45.0, help="excerpt length, s (default 45)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1], help="listening stretch-set seeds (default 0 1)")
    p.add_argument("--sets", default="own,listening,style,folders",
                   help="comma-separated: own, listening, style, folders (default all)")
    p.add_argument("--chooser", choices=("codes", "match"), default="codes",
                   help="what picks the library's movements: codes (the default's predictor, shipped) or match "
                        "(music descriptors -> nearest windows, issue 40's second design; docs/library.md)")
    p.add_argument("--no-folder-choice", action="store_true",
                   help="every set but folders with library_folders.FOLDER_CHOICE off: under auto the stream matches "
                        "among every folder's exemplars (and keeps to the one it starts in); the baseline")
    p.add_argument("--cache", type=Path, default=REPO / ".cache" / "library_play", help="DWM frames cache")
    p.add_argument("--out", type=Path, default=REPO / "runs" / "library_play", help="report folder")
    p.add_argument("--save-checkpoint", type=Path, metavar="OUT.pt",
                   help="only write the library performer as a checkpoint (its folders' names and priors dropped: "
                        "it dances auto; and its own choice: one code a step, library_hops.py measures that) "
                        "for `performer bench latency --checkpoint OUT.pt`, and stop")
    p.add_argument("--write-dwm", nargs="+", metavar=("DIR", "DANCE"),
                   help="only write these DWM dances as BVH into DIR (e.g. DIR DANCE_C_2 DANCE_R_5 DANCE_W_5) and stop")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    a = parse_args(argv)
    import torch

    from models.errors import PerformerError

    torch.set_num_threads(1)
    if a.no_folder_choice:
        import models.networks.library_folders as lf

        lf.FOLDER_CHOICE = False
    if a.write_dwm:
        try:
            write_dwm(Path(a.write_dwm[0]), a.write_dwm[1:], a.data / "dwm")
        except (PerformerError, OSError) as e:
            print(f"library_play.py: {e}", file=sys.stderr)
            return 2
        return 0
    if a.library is None:
        print("library_play.py: give --library FILE.npz (or --write-dwm)", file=sys.stderr)
        return 2
    from models.data.library import load_library
    from models.evaluation import listening as L
    from models.features.spectral import extract_features
    from models.generate import load_model
    from models.data.library import clip_tracks
    from models.generate import load_library_model
    from models.networks.library_player import STYLE_BASE

    try:
        lm = load_model(None)
        clips = load_library(a.library)
        lib = load_library_model(lm.model, a.library, chooser=a.chooser)
        music = L.music_files(a.data / "music")
    except (PerformerError, OSError) as e:
        print(f"library_play.py: {e}", file=sys.stderr)
        return 2
    if a.save_checkpoint:
        import torch

        from models.training.style_memory import save_as_loaded

        lib.style_prior = lib.style_prior[:, :4].contiguous()  # the checkpoint format's four columns
        lib.member_style = torch.where(lib.member_style >= STYLE_BASE, 0, lib.member_style)
        save_as_loaded(type(lm)(lib, lm.meta, lm.features, lm.path), str(a.save_checkpoint))
        print(f"wrote {a.save_checkpoint}: {lib.config.members} exemplars a code, "
              f"{int(lib.member_count.sum())} in all")
        return 0
    sets = set(a.sets.split(","))
    user = np.concatenate([body_frame(clip_tracks(c.motion)[0]) for c in clips])
    folders = {f: np.concatenate([body_frame(clip_tracks(c.motion)[0]) for c in clips if c.folder == f])
               for f in lib.library_styles}
    near_user = Nearest(user)
    cache = L.AudioCache(a.cache / "audio")
    report: dict = {"library": str(a.library), "chooser": a.chooser, "clips": [c.name for c in clips], "folders": list(lib.library_styles),
                    "clip_bpm": [round(1800.0 / p, 1) if p else 0.0 for p in lib.clip_periods], "songs": {}}
    print(f"library {a.library}: {len(clips)} clips, folders {', '.join(lib.library_styles)}, tempi "
          f"{report['clip_bpm']} bpm; {lib.config.members} exemplars a code")
    if sets & {"own", "style", "folders"}:
        if "own" in sets:
            skip = {c.name for c in clips}
            near_dwm = Nearest(dwm_frames(a.data / "dwm", a.cache, skip))
            report["dwm_left_out"] = sorted(skip & {d.name for d in (a.data / "dwm").iterdir()})
            windows = member_windows(lib, [clip_tracks(c.motion)[0] for c in clips])
        tot = {"lib": [], "lib_dwm": [], "def_user": [], "def_dwm": [], "lib_tok": []}
        print(f"{'recording':<38} {'lib: nearer user':>16} {'median cm':>9} {'seam':>5} | {'default: nearer user':>20} "
              f"{'to DWM cm':>9} {'seam':>5}" + "".join(f" {'style ' + f:>14}" for f in lib.library_styles))
        for p in music:
            y = cache.audio(p)
            y = y[int(a.start * L.SAMPLE_RATE): int((a.start + a.seconds) * L.SAMPLE_RATE)]
            feats = extract_features(y, lm.features)
            row: dict = {}
            if "own" in sets:
                for key, model in (("lib", lib), ("default", lm.model)):
                    bends: list = []
                    poses, dance, token, cont = perform(model, feats, windows=windows if key == "lib" else None,
                                                        bends=bends)
                    pts = body_frame(poses[dance])
                    du, dd = near_user(pts), near_dwm(pts)
                    by = {f: float((du < dd)[token[dance] == STYLE_BASE + i].mean())
                          for i, f in enumerate(lib.library_styles) if (token[dance] == STYLE_BASE + i).any()}
                    row[key] = {"frames": int(dance.sum()), "nearer_user": float((du < dd).mean()),
                                "nearer_user_by_folder": by if key == "lib" else {},
                                "median_user_cm": float(np.median(du) * 100), "median_dwm_cm": float(np.median(dd) * 100),
                                "seam": handover_seam(model, poses), "continues": cont,
                                "bend_median_deg": float(np.median(bends)) if bends else float("nan"),
                                "bend_max_deg": float(np.max(bends)) if bends else float("nan")}
                    tot["lib" if key == "lib" else "def_user"].append(du)
                    tot["lib_dwm" if key == "lib" else "def_dwm"].append(dd)
                    if key == "lib":
                        tot["lib_tok"].append(token[dance])
            if "style" in sets and len(folders) > 1:
                for i, (f, own) in enumerate(folders.items()):
                    poses, dance, token, _ = perform(lib, feats, style=f)
                    pts = body_frame(poses[dance])
                    others = np.min([Nearest(x)(pts) for g, x in folders.items() if g != f], axis=0)
                    row.setdefault("style", {})[f] = float((token[dance] == STYLE_BASE + i).mean())
                    row.setdefault("style_nearer", {})[f] = float((Nearest(own)(pts) < others).mean())
            if "folders" in sets and len(folders) > 1:
                row["folders"] = folder_shares(lib, feats)
                print(f"  {p.stem[:30]} auto folders (token: frames), choice off / on: "
                      + " / ".join(f"{row['folders'][k]['tokens']} {row['folders'][k]['changes']} changes, seam "
                                   f"{row['folders'][k]['seam']:.2f}" for k in ("off", "on")), flush=True)
            report["songs"][p.stem] = row
            li, de = row.get("lib", {}), row.get("default", {})
            print(f"{p.stem[:38]:<38} {li.get('nearer_user', np.nan):16.3f} {li.get('median_user_cm', np.nan):9.2f} "
                  f"{li.get('seam', np.nan):5.2f} | {de.get('nearer_user', np.nan):20.3f} "
                  f"{de.get('median_dwm_cm', np.nan):9.2f} {de.get('seam', np.nan):5.2f}"
                  + "".join(f" {row.get('style', {}).get(f, np.nan):6.3f}/{row.get('style_nearer', {}).get(f, np.nan):.3f}"
                            for f in lib.library_styles), flush=True)
        if "own" in sets:
            du, dd = np.concatenate(tot["lib"]), np.concatenate(tot["lib_dwm"])
            bu, bd = np.concatenate(tot["def_user"]), np.concatenate(tot["def_dwm"])
            report["nearer_user"] = float((du < dd).mean())
            report["median_cm"] = float(np.median(du) * 100)
            tok = np.concatenate(tot["lib_tok"])
            report["nearer_user_by_folder"] = {f: float((du < dd)[tok == STYLE_BASE + i].mean())
                                               for i, f in enumerate(lib.library_styles) if (tok == STYLE_BASE + i).any()}
            print(f"library frames nearer the user's clips, by the folder of the exemplar playing: "
                  + ", ".join(f"{f} {v:.3f}" for f, v in report["nearer_user_by_folder"].items()))
            report["seam"] = max(r["lib"]["seam"] for r in report["songs"].values())
            report["continues"] = float(np.nanmean([r["lib"]["continues"] for r in report["songs"].values()]))
            for key in ("lib", "default"):
                print(f"handover bend ({key}), degrees a bone, median / largest by recording: " + ", ".join(
                    f"{n.split('_')[0]} {r[key]['bend_median_deg']:.1f}/{r[key]['bend_max_deg']:.0f}"
                    for n, r in report["songs"].items()))
            print(f"code steps whose exemplar continues the playing window (same clip, {lib.config.seg} +- "
                  f"{lib.config.seg // 2} frames on), "
                  f"mean of recordings: {report['continues']:.3f}")
            report["default"] = {"nearer_user": float((bu < bd).mean()), "median_dwm_cm": float(np.median(bd) * 100),
                                 "seam": max(r["default"]["seam"] for r in report["songs"].values())}
        if "folders" in sets and len(folders) > 1:
            report["folders"] = summarize_folders([r["folders"] for r in report["songs"].values()], lib.library_styles)
        if "style" in sets and len(folders) > 1:
            report["style_min"] = min(v for r in report["songs"].values() for v in r["style"].values())
            report["style_nearer_min"] = min(v for r in report["songs"].values() for v in r["style_nearer"].values())
            report["style_nearer_mean"] = float(np.mean([v for r in report["songs"].values()
                                                          for v in r["style_nearer"].values()]))
    if "listening" in sets:
        opts = L.Options(music=a.data / "music", cache_dir=a.cache / "audio", seeds=tuple(a.seeds), progress=False,
                         sets=("stretch", "presence"))
        songs = L.stretch_songs(cache, opts)
        for key, model in (("lib", lib), ("default", lm.model)):
            m = type(lm)(model, lm.meta, lm.features, lm.path)
            rows = L.stretch_set(m, cache, songs, opts)
            hit = float(np.mean([r["rates"]["1"]["hit"] for r in rows]))
            half = float(np.mean([r["rates"]["1"]["hit_half"] for r in rows]))
            got = {"speed_ratio": float(np.mean([r["speed_ratio"] for r in rows])), "hit": hit, "hit_control": half,
                   "hit_over_control": hit / max(half, 1e-9), "songs": [r["song"] for r in rows],
                   "speed_ratio_by_song": {r["song"]: r["speed_ratio"] for r in rows},
                   # each seed's own: the mean over the songs of that seed's ratio (one draw of the choices)
                   "speed_ratio_by_seed": {str(sd): float(np.mean([r["by_seed"][str(sd)]["speed_ratio"] for r in rows]))
                                           for sd in a.seeds}}
            got["speed_ratio_seed_min"] = min(got["speed_ratio_by_seed"].values())
            pres = L.presence(m, cache, None, opts)["music"]
            got["idle_max"] = max(r["idle_sounding"] for r in pres)
            got["idle_by_song"] = {r["recording"]: r["idle_sounding"] for r in pres}
            print(f"listening {key}: speed ratio 1.25x/0.8x {got['speed_ratio']:.2f} over {len(rows)} recordings, "
                  f"beat hit {hit:.3f} (control {half:.3f}, {got['hit_over_control']:.2f}x), "
                  f"largest idle share {got['idle_max']:.3f}; speed ratio by seed "
                  + ", ".join(f"{k} {v:.2f}" for k, v in got["speed_ratio_by_seed"].items()), flush=True)
            if key == "lib":
                report.update({k: got[k] for k in ("speed_ratio", "speed_ratio_seed_min", "hit", "hit_over_control", "idle_max")})
            report.setdefault("listening", {})[key] = got
    if "default" in report:
        d = report["default"]
        print(f"default baseline: {d['nearer_user']:.3f} of its frames nearer the library's clips, median "
              f"{d['median_dwm_cm']:.2f} cm to the nearest DWM frame, worst seam {d['seam']:.2f}")
    ok = True
    for key, op, lim in TARGETS:
        if key in report:
            good = report[key] >= lim if op == ">=" else report[key] <= lim
            ok &= good
            print(f"{'PASS' if good else 'FAIL'} {key} {report[key]:.3f} (target {op} {lim})")
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "library_play.json").write_text(json.dumps(report, indent=1, default=float))
    print(f"wrote {a.out / 'library_play.json'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())

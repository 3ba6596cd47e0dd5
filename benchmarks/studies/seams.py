"""Window seams of causal checkpoints on real music (issue #3, acceptance (c)).

For each checkpoint and song, generates the motion the way ``performer run`` streams it
(``run_model``: 128-frame windows, 64-frame hop, rotation-aware crossfade; equal to the
streamed output, tests/test_generate.py) and prints ``seam_ratio``: the mean angular
acceleration of the frames within 2 of a window boundary over that of the other frames
(target: at most 1.2; 1.0 means the boundaries are invisible). A ``dance_vq`` checkpoint
(the dancing performer) has no windows to blend; its seams are its handovers, where one real
exemplar hands over to the next (inertialization), so for it the ratio is taken at every
handover with a radius of 1 frame. The code step is frame ``8k``, but the beat warp plays
the movement about ``WARP_LAG`` (1.5) frames late, so the handover shows at frame
``8k + round(WARP_LAG)`` (8k + 2): there the ratio is centred (``--handover-offset`` sets
another; the old centre, 0, sits in the calm just before the handover and reads a seam as
smaller than the motion around it)::

    .venv/bin/python benchmarks/studies/seams.py --checkpoint models/assets/default.pt \\
        --audio models/assets/clip.ogg /path/to/dwm/DANCE_W_5/audio.mp3

Prints a Markdown table (rows: songs, columns: checkpoints). Exit status 2 on a missing
or unreadable file, 1 when a ratio exceeds ``--max``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def handover_offset() -> int:
    """Frames from a dance_vq code step (8k) to where its movement's handover shows: the beat
    warp's mean lag, rounded (``models.networks.player.WARP_LAG``)."""
    from models.networks.player import WARP_LAG

    return int(round(WARP_LAG))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--checkpoint", nargs="+", default=["models/assets/default.pt"], help="causal checkpoints")
    p.add_argument("--audio", nargs="+", default=None, help="songs (default: the bundled clip)")
    p.add_argument("--window", type=int, default=128, help="window in frames (default 128)")
    p.add_argument("--hop", type=int, default=64, help="hop in frames (default 64)")
    p.add_argument("--max", type=float, default=1.2, help="exit 1 above this ratio (default 1.2)")
    p.add_argument("--handover-offset", type=int, default=None, metavar="FRAMES",
                   help="dance_vq: frames from the code step 8k to the handover the ratio is centred on "
                        "(default round(WARP_LAG) of models/networks/player.py: 2)")
    a = p.parse_args(argv)
    import torch

    from models.errors import CheckpointError, DataError
    from models.features.audio_io import bundled_clip_path, load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model, run_model
    from models.networks.blend import seam_ratio

    torch.set_num_threads(1)
    songs = [Path(s) for s in (a.audio or [bundled_clip_path()])]
    try:
        models = [load_model(c) for c in a.checkpoint]
        audio = {s: load_audio(s)[0] for s in songs}
    except (CheckpointError, DataError, OSError) as e:
        print(f"seams.py: {e}", file=sys.stderr)
        return 2
    if any(m.name not in ("causal", "dance_vq") for m in models):
        print("seams.py: only causal checkpoints (windows) and dance_vq ones (movements) stream", file=sys.stderr)
        return 2
    print("| song | " + " | ".join(a.checkpoint) + " |")
    print("| --- |" + " ---: |" * len(models))
    worst = 0.0
    for song, samples in audio.items():
        ratios = []
        for m in models:
            poses = run_model(m.model, extract_features(samples, m.features), window=a.window, hop=a.hop)
            if m.name == "dance_vq":
                seg = m.model.config.seg
                off = handover_offset() if a.handover_offset is None else a.handover_offset
                ratios.append(seam_ratio(poses[off % seg:], seg, seg, radius=1))  # frame 0 = a handover
            else:
                ratios.append(seam_ratio(poses, a.window, a.hop))
        worst = max(worst, *ratios)
        print(f"| {song.parent.name if song.name == 'audio.mp3' else song.name} | " + " | ".join(f"{r:.3f}" for r in ratios) + " |")
    return 1 if worst > a.max else 0


if __name__ == "__main__":
    sys.exit(main())

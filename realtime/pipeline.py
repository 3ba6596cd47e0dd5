"""The one place where a checkpoint becomes the engine's feature stream and pose model.

:func:`build_pipeline` loads a checkpoint with :func:`models.networks.checkpoint.load_checkpoint`,
rebuilds the feature configuration it was trained with, and returns

* ``extractor_factory(input_sr)`` → a fresh :class:`models.features.streaming.StreamingFeatureExtractor`;
* ``model`` → a :class:`models.networks.streaming.StreamingGenerator` (128-frame windows,
  64-frame hop, overlap blending), which is an engine :class:`~realtime.contracts.PoseModel`.

Without ``--checkpoint`` the packaged default ``models/assets/default.pt`` is used.

``python -m realtime.pipeline [--checkpoint CKPT] [--seconds S] [--threads 1 2] [--paced] [--repeat N]``
measures the engine's per-hop compute time (features + model + blending + guard and
smoothing, no network) on S seconds of noise replayed as fast as possible (``--paced``:
in real time, also reporting block-release-to-send latency); without a
checkpoint (and none packaged) it uses a default-size causal generator with random
weights (same compute as a trained one).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from models.errors import CheckpointError, PerformerError
from models.generate import DEFAULT_CHECKPOINT, default_checkpoint_path, load_model  # noqa: F401  (re-exported)
from realtime.contracts import ExtractorFactory, PoseModel


@dataclass
class Pipeline:
    """What :func:`build_pipeline` returns: the engine's two model-side inputs, plus provenance.

    ``feature_key``: the feature config's fingerprint; an ensemble's performers with equal
    keys share one extractor (:class:`realtime.performer.Performer`)."""

    extractor_factory: ExtractorFactory
    model: PoseModel
    checkpoint: Path
    meta: dict = field(default_factory=dict)
    feature_key: str | None = None


def _load(checkpoint, library, mix: bool):
    """:func:`load_model` of ``checkpoint``, its memory replaced by (or mixed with) ``library``."""
    from models.generate import with_library

    return with_library(load_model(checkpoint), library, mix)


def build_pipeline(checkpoint: str | Path | None = None, *, window: int = 128, hop: int = 64, seed: int = 0,
                   style: str | None = None, energy: float = 1.0, lead: float = 0.0,
                   stage: str | float | None = None, facing: str = "free", spot: tuple[int, int] | None = None,
                   loaded: dict | None = None, library: str | Path | None = None, mix: bool = False) -> Pipeline:
    """Load ``checkpoint`` (default: the packaged one) into an extractor factory and a pose model.

    ``loaded``: a dict kept by the caller across calls (an ensemble's performers): a
    checkpoint already loaded through it is reused (its network is read-only while
    streaming; each call still builds its own stream with its own state), so N performers
    of one checkpoint load it once and hold its weights once.

    Raises :class:`CheckpointError` naming the file if it is missing, unreadable, not a
    causal model, or made for another rig or feature code. A model that declares
    ``offline_only`` (``violin``, ``dtm``: they read future frames) is refused with one
    line saying so and why (its ``offline_reason``), before any streaming state is built.
    A ``dance_vq`` model streams as a :class:`~models.networks.dance_stream.DanceStream`
    with ``seed``, ``style`` (None: the music decides) and ``energy`` (0..2, 1: as the music
    asks; :meth:`~models.networks.dance_stream.DanceStream.set_energy`) and ``lead`` (ms, 0..200:
    :meth:`~models.networks.dance_stream.DanceStream.set_lead`), on ``stage`` (``"WxD"`` metres or
    0: in place; None: :data:`models.networks.stage.DEFAULT_STAGE`) facing ``facing`` (free,
    audience; docs/stage.md), ``spot`` (i, n): performer i of an ensemble of n on its own part
    of that stage (:class:`models.networks.stage.SpotStage`); a style, an energy other than 1,
    a lead other than 0, a stage or facing audience for another model is refused.
    """
    from models.features.streaming import StreamingFeatureExtractor
    from models.networks.streaming import StreamingGenerator

    if loaded is None:
        loaded_model = _load(checkpoint, library, mix)
    else:
        key = str(Path(checkpoint).resolve()) if checkpoint is not None else None
        if library is not None:
            key = (key, str(Path(library).resolve()), bool(mix))
        if key not in loaded:
            loaded[key] = _load(checkpoint, library, mix)
        loaded_model = loaded[key]
    loaded = loaded_model
    path, meta, cfg = loaded.path, loaded.meta, loaded.features
    if getattr(loaded.model, "offline_only", False):  # e.g. dtm: needs the whole song's beats up front
        reason = getattr(loaded.model, "offline_reason", "it needs the whole song")
        raise CheckpointError(f"model {loaded.name!r} is offline-only ({reason}); it cannot run live: "
                              "use `performer generate` or `performer evaluate`", source=path)
    try:
        if getattr(loaded.model, "takes_style", False):
            from models.networks.dance_stream import DanceStream

            from models.networks.stage import DEFAULT_STAGE

            generator = DanceStream(loaded.model, seed=seed, style=style, energy=energy, lead_ms=lead,
                                    stage=DEFAULT_STAGE if stage is None else stage, facing=facing, spot=spot)
        else:
            if style not in (None, "auto"):
                raise CheckpointError(f"model {loaded.name!r} takes no style (--style needs a dance_vq model)",
                                      source=path)
            if energy != 1.0:
                raise CheckpointError(f"model {loaded.name!r} has no energy control (--energy needs a dance_vq "
                                      "model)", source=path)
            if lead != 0.0:
                raise CheckpointError(f"model {loaded.name!r} has no lead control (--lead needs a dance_vq model)",
                                      source=path)
            if stage not in (None, 0, "0") or facing != "free":
                raise CheckpointError(f"model {loaded.name!r} has no stage (--stage and --facing need a dance_vq "
                                      "model)", source=path)
            generator = StreamingGenerator(loaded.model, window=window, hop=hop)
    except CheckpointError:
        raise
    except PerformerError as exc:
        raise CheckpointError(f"model {meta.get('model_name')!r} cannot stream: {exc}", source=path) from None

    def extractor_factory(input_sr: int) -> StreamingFeatureExtractor:
        return StreamingFeatureExtractor(cfg, input_sr)

    return Pipeline(extractor_factory, generator, path, meta, feature_key=cfg.fingerprint())


def random_pipeline(seed: int = 0) -> Pipeline:
    """Default-size causal generator with random weights and default features (benchmarks only)."""
    import torch

    from models.features.spectral import FeatureConfig
    from models.features.streaming import StreamingFeatureExtractor
    from models.networks.checkpoint import build_model
    from models.networks.streaming import StreamingGenerator

    torch.manual_seed(seed)
    cfg = FeatureConfig()
    generator = StreamingGenerator(build_model("causal", {"feature_dim": cfg.dim}))
    return Pipeline(lambda sr: StreamingFeatureExtractor(cfg, sr), generator, Path("random-weights"), {},
                    feature_key=cfg.fingerprint())


def _bench(pipeline: Pipeline, seconds: float, threads: int, sample_rate: int, block: int, paced: bool) -> dict:
    import time

    import numpy as np

    from realtime.audio_input import FileSource
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig

    audio = 0.2 * np.random.default_rng(0).standard_normal(int(seconds * sample_rate)).astype(np.float32)
    src = FileSource(audio, sample_rate, block_size=block, realtime=paced, name="noise")
    eng = Engine(src, pipeline.extractor_factory, pipeline.model, [],
                 EngineConfig(threads=threads, max_read=block, stats_size=int(seconds * 30) + 1))
    eng.start()
    cpu0 = time.process_time()
    eng.wait()
    cpu = time.process_time() - cpu0
    eng.close()
    return {**eng.stats(), "cpu_ms_per_frame": 1000.0 * cpu / max(1, eng.frames_out)}


def main(argv: list[str] | None = None) -> int:
    """``python -m realtime.pipeline``: per-hop compute time of the real pipeline."""
    import argparse

    p = argparse.ArgumentParser(description=main.__doc__)
    p.add_argument("--checkpoint", help="checkpoint (default: packaged one, else random weights)")
    p.add_argument("--seconds", type=float, default=30.0, help="seconds of noise (default 30)")
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="torch thread counts to compare")
    p.add_argument("--sample-rate", type=int, default=44100, help="input rate, Hz (default 44100)")
    p.add_argument("--block-size", type=int, default=512, help="samples per push (default 512)")
    p.add_argument("--paced", action="store_true", help="replay in real time and also report latency")
    p.add_argument("--repeat", type=int, default=1, help="runs per thread count, interleaved (default 1)")
    args = p.parse_args(argv)
    if args.checkpoint is None and not default_checkpoint_path().is_file():
        pipeline = random_pipeline()
    else:
        pipeline = build_pipeline(args.checkpoint)
    for threads in [t for _ in range(args.repeat) for t in args.threads]:
        st = _bench(pipeline, args.seconds, threads, args.sample_rate, args.block_size, args.paced)
        line = (f"{pipeline.checkpoint.name}: threads={threads} input {args.sample_rate} Hz blocks of "
                f"{args.block_size}{' paced' if args.paced else ''}: {st['frames']} frames, per-hop compute "
                f"p50 {st['compute_ms_p50']:.2f} ms p99 {st['compute_ms_p99']:.2f} ms, "
                f"process CPU {st['cpu_ms_per_frame']:.2f} ms/frame")
        if args.paced:
            line += f"; block release -> send p50 {st['latency_ms_p50']:.2f} ms p99 {st['latency_ms_p99']:.2f} ms"
        print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

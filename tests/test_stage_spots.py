"""An ensemble on one stage (issue 39): each performer its own spot (models/networks/stage.py,
ensemble_spots, SpotStage), inside it on every frame, never within MIN_SEPARATION of another;
`performer run` gives an ensemble its spots and tells the viewer."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from test_dance_vq import music
from test_stage import walking_model

from models.errors import ConfigError
from models.networks.dance_stream import DanceStream
from models.networks.stage import MAX_SPEED, MIN_SEPARATION, SpotStage, ensemble_spots
from models.timebase import FPS


@pytest.mark.parametrize("stage, n", [("3x2", 2), ("3x2", 4), ("6x5", 4), ("3x2", 3), ("6x5", 7), ("1x1", 2)])
def test_spots_lie_inside_the_stage_and_at_least_the_separation_apart(stage, n):
    w, d = (float(v) for v in stage.split("x"))
    spots = ensemble_spots(stage, n)
    assert len(spots) == n
    boxes = [(cx - sw / 2, cx + sw / 2, cz - sd / 2, cz + sd / 2) for cx, cz, sw, sd in spots]
    for x0, x1, z0, z1 in boxes:
        assert -w / 2 - 1e-9 <= x0 < x1 <= w / 2 + 1e-9 and -d / 2 - 1e-9 <= z0 < z1 <= d / 2 + 1e-9
    for a, b in itertools.combinations(boxes, 2):  # apart along x or along z by the separation
        gap_x = max(b[0] - a[1], a[0] - b[1])
        gap_z = max(b[2] - a[3], a[2] - b[3])
        assert max(gap_x, gap_z) >= MIN_SEPARATION - 1e-9


def test_too_many_performers_for_a_stage_is_a_one_line_error_and_stage_0_is_in_place():
    with pytest.raises(ConfigError, match="no room for 9 performers") as e:
        ensemble_spots("1x1", 9)
    assert "\n" not in str(e.value)
    assert ensemble_spots("0", 3) == [(0.0, 0.0, 0.0, 0.0)] * 3


def _roots(streams: list[DanceStream], x: np.ndarray) -> np.ndarray:
    """(n, T, 2) root x, z of each stream on the same music."""
    return np.stack([s.push(x)[:, [0, 2]] for s in streams])


def test_each_performer_stays_in_its_spot_and_they_never_come_closer_than_the_separation():
    """Four performers who all walk straight on (the same exemplars, the same seed) on a 3x2 stage
    for a minute: every frame inside each one's spot, never closer than 0.6 m. Without the spots
    (each on the whole stage) they walk the same path: this fails."""
    m = walking_model(speed=0.02, turn=0.0)
    x = music(1800)
    spots = ensemble_spots("3x2", 4)
    roots = _roots([DanceStream(m, seed=1, stage="3x2", spot=(i, 4)) for i in range(4)], x)
    for (cx, cz, w, d), r in zip(spots, roots):
        assert (np.abs(r[:, 0] - cx) <= w / 2 + 1e-6).all() and (np.abs(r[:, 1] - cz) <= d / 2 + 1e-6).all()
        step = np.linalg.norm(np.diff(r, axis=0), axis=1)
        assert step.max() <= MAX_SPEED / FPS + 1e-6  # no jump
        assert step[900:].sum() > 0.1  # still dancing along in the second half minute
    apart = min(np.linalg.norm(a - b, axis=1).min() for a, b in itertools.combinations(roots, 2))
    assert apart >= MIN_SEPARATION
    shared = _roots([DanceStream(m, seed=1, stage="3x2") for _ in range(2)], x)
    assert np.linalg.norm(shared[0] - shared[1], axis=1).min() < MIN_SEPARATION  # the control: they meet


def test_a_new_stage_set_live_recuts_the_spots_and_each_walks_into_its_own_without_a_jump():
    m = walking_model(speed=0.02, turn=0.01)
    x = music(1200)
    s = DanceStream(m, seed=2, stage="6x5", spot=(3, 4))
    first = s.push(x[:600])[:, [0, 2]]
    s.set_stage("3x2")
    then = s.push(x[600:])[:, [0, 2]]
    both = np.concatenate([first, then])
    assert np.linalg.norm(np.diff(both, axis=0), axis=1).max() <= MAX_SPEED / FPS + 0.6 / FPS + 1e-6
    cx, cz, w, d = ensemble_spots("3x2", 4)[3]
    late = then[-150:]
    assert (np.abs(late[:, 0] - cx) <= w / 2 + 1e-6).all() and (np.abs(late[:, 1] - cz) <= d / 2 + 1e-6).all()
    assert s.stage.state() == {"stage": [3.0, 2.0], "facing": "free", "spot": [cx, cz, w, d],
                               "spots": [list(sp) for sp in ensemble_spots("3x2", 4)]}  # the viewer draws them all
    with pytest.raises(ConfigError, match="no room"):
        s.set_stage("0.6x0.6")  # 4 on 0.6x0.6: refused, nothing changed
    assert s.stage.whole == (3.0, 2.0)
    with pytest.raises(ConfigError, match="no spot"):
        SpotStage(16, "3x2", "free", (4, 4))


def test_run_gives_an_ensemble_its_spots_and_names_them(tmp_path, capsys):
    """`performer run` with two performers on --stage 3x2: each recording stays inside its spot
    (left and right halves, 1.2 m wide), and the run's description names each spot."""
    from models.features.audio_io import bundled_clip_path
    from models.rig.npz import load_npz_extra
    from realtime import cli

    code = cli.main(["run", "--audio", str(bundled_clip_path()), "--fast", "--no-ws", "--no-osc",
                     "--warmup", "0", "--stage", "3x2", "--performer", f"a,record={tmp_path / 'a.npz'}",
                     "--performer", f"b,record={tmp_path / 'b.npz'}"])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "spot 1.2x2 m at (-0.90, +0.00)" in err and "spot 1.2x2 m at (+0.90, +0.00)" in err
    a, b = (load_npz_extra(tmp_path / f"{n}.npz")["pose"][:, [0, 2]] for n in "ab")
    assert (a[:, 0] <= -0.3 + 1e-6).all() and (b[:, 0] >= 0.3 - 1e-6).all()
    n = min(len(a), len(b))
    assert np.linalg.norm(a[:n] - b[:n], axis=1).min() >= MIN_SEPARATION


def test_a_reload_of_an_ensemble_recuts_every_performers_spot(tmp_path):
    """SIGHUP's reload (run.reload_settings) on a real two-performer engine: a new stage in the
    file reaches both performers' models, each with its own spot of it, and the viewer's state."""
    import numpy as np  # noqa: F811 - local for clarity

    from models.timebase import SAMPLE_RATE
    from realtime import cli
    from realtime.audio_input import FileSource
    from realtime.commands.run import reload_settings
    from realtime.config import resolve_run_config
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.performer import Performer
    from realtime.pipeline import build_pipeline

    conf = tmp_path / "show.toml"
    conf.write_text('audio = "x.wav"\nstage = "3x2"\n[[performer]]\nname = "a"\n[[performer]]\nname = "b"\n')
    args = cli.build_parser().parse_args(["run", "--config", str(conf)])
    cfg = resolve_run_config(args)
    loaded: dict = {}
    perfs = []
    for k, name in enumerate("ab"):
        p = build_pipeline(None, seed=k, loaded=loaded, stage=cfg.stage, spot=(k, 2))
        perfs.append(Performer(name, p.model, p.extractor_factory, [], feature_key=p.feature_key))
    eng = Engine(FileSource(np.zeros(SAMPLE_RATE, np.float32), SAMPLE_RATE), config=EngineConfig(), performers=perfs)
    try:
        assert [p.model.stage.state()["spot"] for p in perfs] == [[-0.9, 0.0, 1.2, 2.0], [0.9, 0.0, 1.2, 2.0]]
        conf.write_text('audio = "x.wav"\nstage = "6x5"\nfacing = "audience"\n'
                        '[[performer]]\nname = "a"\n[[performer]]\nname = "b"\n')
        cfg = reload_settings(args, eng, cfg)
        assert (cfg.stage, cfg.facing) == ("6x5", "audience")
        states = [p.model.stage.state() for p in perfs]
        assert [s["spot"] for s in states] == [[-1.65, 0.0, 2.7, 5.0], [1.65, 0.0, 2.7, 5.0]]
        assert all(s["stage"] == [6.0, 5.0] and s["facing"] == "audience" for s in states)
    finally:
        eng.close()

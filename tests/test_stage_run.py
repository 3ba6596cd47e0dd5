"""`performer run` and the stage (issue 39): --stage/--facing flags and config keys reach the
dancing model, a reload applies them live, bad values and unsupported combinations are one line."""

from __future__ import annotations

import argparse

import pytest
from test_run_cli import clip, one_line_error, tiny_checkpoint  # noqa: F401 - fixtures

from models.errors import ConfigError
from realtime import cli
from realtime.config import RunConfig, live_changes, load_run_config, resolve_run_config
from realtime.pipeline import build_pipeline


def test_stage_and_facing_reach_the_model_from_flags_and_the_config_file(tmp_path):
    conf = tmp_path / "show.toml"
    conf.write_text('audio = "x.wav"\nstage = "6x5"\nfacing = "audience"\n')
    cfg = resolve_run_config(argparse.Namespace(config=str(conf)))
    assert (cfg.stage, cfg.facing) == ("6x5", "audience")
    s = build_pipeline(None, stage=cfg.stage, facing=cfg.facing).model.stage
    assert (s.width, s.depth, s.facing) == (6.0, 5.0, "audience")
    flags = resolve_run_config(argparse.Namespace(config=str(conf), stage="0", facing=None))
    assert build_pipeline(None, stage=flags.stage).model.stage.active is False  # a flag wins over the file
    default = build_pipeline(None).model.stage  # no stage given: a screen's or small stage's 3x2
    assert (default.width, default.depth, default.facing) == (3.0, 2.0, "free")
    assert load_run_config(conf)["stage"] == "6x5"


@pytest.mark.parametrize("kw, needle", [({"stage": "6y5"}, "stage must be WxD"),
                                        ({"facing": "back"}, "facing must be one of free, audience"),
                                        ({"stage": "0x3"}, "stage sides")])
def test_bad_stage_values_are_one_line_config_errors(kw, needle):
    with pytest.raises(ConfigError, match=needle) as e:
        RunConfig(audio="x.wav", **kw).validate()
    assert "\n" not in str(e.value)


def test_a_stage_for_a_model_without_one_is_refused(capsys, clip, tiny_checkpoint):  # noqa: F811
    code = cli.main(["run", "--audio", str(clip), "--fast", "--no-ws", "--no-osc", "--checkpoint", str(tiny_checkpoint),
                     "--stage", "3x2"])
    assert code == 2 and "has no stage" in one_line_error(capsys.readouterr().err)
    code = cli.main(["run", "--audio", str(clip), "--fast", "--no-ws", "--no-osc", "--checkpoint", str(tiny_checkpoint)])
    assert code == 0  # the default stage is the dancing model's: another model runs as before
    capsys.readouterr()
    code = cli.main(["run", "--audio", str(clip), "--fast", "--no-ws", "--no-osc", "--performer", "a",
                     "--performer", "b", "--performer", "c", "--stage", "0.5x0.5"])
    assert code == 2 and "no room for 3 performers" in one_line_error(capsys.readouterr().err)  # tests/test_stage_spots.py


def test_a_reload_applies_stage_and_facing_live(monkeypatch):
    """SIGHUP's reload sends a changed stage or facing to the running model as controls."""
    from realtime.commands.run import reload_settings

    class Engine:
        def __init__(self):
            self.calls = []

        def update(self, **kw):
            self.calls.append(("update", kw))

        def control(self, action, value=None, performer=None):
            self.calls.append((action, value))

    old = RunConfig(audio="x.wav", stage="3x2").validate()
    new = RunConfig(audio="x.wav", stage="6x5", facing="audience").validate()
    live, other = live_changes(old, new)
    assert set(other) >= {"stage", "facing"}  # not engine settings: reload_settings sends them
    engine = Engine()
    monkeypatch.setattr("realtime.config.resolve_run_config", lambda args: new)
    kept = reload_settings(argparse.Namespace(config="show.toml"), engine, old)
    assert ("stage", "6x5") in engine.calls and ("facing", "audience") in engine.calls
    assert (kept.stage, kept.facing) == ("6x5", "audience")

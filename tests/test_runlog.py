"""log.csv and losses.png of a training run (models.training.runlog)."""

from __future__ import annotations

import csv

from models.training.runlog import RunLog

FIELDS = ["step", "loss_a", "loss_gan", "val_x"]
PANELS = (("losses", ("loss_a",), True), ("GAN", ("loss_gan",), False), ("validation", ("val_x",), False))


def rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_resume_cuts_the_log_back_to_the_saved_step(tmp_path):
    log = RunLog(tmp_path, FIELDS, PANELS)
    log.start()
    for step in range(1, 8):
        log.append({"step": step, "loss_a": 1.0 / step, "val_x": 0.5 if step % 3 == 0 else ""})
    assert [r["step"] for r in rows(log.path)] == [str(s) for s in range(1, 8)]
    RunLog(tmp_path, FIELDS, PANELS).start(resume_step=4)  # state.pt was saved at step 4
    assert [r["step"] for r in rows(log.path)] == ["1", "2", "3", "4"]
    assert rows(log.path)[2]["val_x"] == "0.5" and rows(log.path)[0]["loss_gan"] == ""
    RunLog(tmp_path, FIELDS, PANELS).start()  # a fresh run starts an empty log
    assert rows(log.path) == []


def test_plot_leaves_out_panels_without_data(tmp_path):
    import matplotlib.image as mpimg

    log = RunLog(tmp_path, FIELDS, PANELS)
    log.start()
    log.plot()  # an empty log draws nothing
    assert not log.png.exists()
    for step in range(1, 21):
        log.append({"step": step, "loss_a": 2.0 / step, "val_x": 0.1 * step if step % 5 == 0 else ""})
    log.plot()
    h, w = mpimg.imread(log.png).shape[:2]
    assert w > 1.5 * h  # two panels side by side (losses, validation), not three
    assert w < 2.6 * h

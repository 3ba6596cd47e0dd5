"""benchmarks/studies/constants.py: a script run with module constants set (issue 43's variants)."""

from __future__ import annotations

import pytest

import models.networks.size_hold as size_hold
from script_loader import load_script

cs = load_script("benchmarks/studies/constants.py")


def test_constants_are_set_before_the_script_runs(tmp_path, monkeypatch, capsys):
    """The assignment reaches the module the script reads, and the script gets its own arguments."""
    monkeypatch.setattr(size_hold, "SIZE_HOLD", size_hold.SIZE_HOLD)  # restored after the test
    script = tmp_path / "probe.py"
    script.write_text("import sys\nimport models.networks.size_hold as h\nprint('read', h.SIZE_HOLD, sys.argv[1:])\n")
    assert cs.main(["models.networks.size_hold.SIZE_HOLD=0.75", "--", str(script), "--x", "1"]) == 0
    out = capsys.readouterr().out
    assert "read 0.75 ['--x', '1']" in out and "SIZE_HOLD=0.75" in out


@pytest.mark.parametrize("bad", ["SIZE_HOLD=1", "models.networks.size_hold.NO_SUCH=1", "models.networks.size_hold.SIZE_HOLD"])
def test_a_misspelt_constant_is_a_one_line_error(bad):
    with pytest.raises(SystemExit, match="constants.py: "):
        cs.apply([bad])

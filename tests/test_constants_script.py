"""benchmarks/studies/constants.py: a script run with module constants set (issue 43's variants)."""

from __future__ import annotations

import pytest

import models.networks.lead as lead
from script_loader import load_script

cs = load_script("benchmarks/studies/constants.py")


def test_constants_are_set_before_the_script_runs(tmp_path, monkeypatch, capsys):
    """The assignment reaches the module the script reads, and the script gets its own arguments."""
    monkeypatch.setattr(lead, "RUNNER_UP_CHANGE", lead.RUNNER_UP_CHANGE)  # restored after the test
    script = tmp_path / "probe.py"
    script.write_text("import sys\nimport models.networks.lead as m\nprint('read', m.RUNNER_UP_CHANGE, sys.argv[1:])\n")
    assert cs.main(["models.networks.lead.RUNNER_UP_CHANGE=0.5", "--", str(script), "--x", "1"]) == 0
    out = capsys.readouterr().out
    assert "read 0.5 ['--x', '1']" in out and "RUNNER_UP_CHANGE=0.5" in out


@pytest.mark.parametrize("bad", ["RUNNER_UP_CHANGE=1", "models.networks.lead.NO_SUCH=1",
                                 "models.networks.lead.RUNNER_UP_CHANGE"])
def test_a_misspelt_constant_is_a_one_line_error(bad):
    with pytest.raises(SystemExit, match="constants.py: "):
        cs.apply([bad])

"""The import contract of pyproject.toml ([tool.importlinter], import-linter's ``lint-imports``):
realtime above models, the layers inside each, no import circle in any package. Imports inside
functions count like module-level ones."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def lint_imports(root: Path) -> subprocess.CompletedProcess:
    """``lint-imports`` on the packages and pyproject.toml under ``root`` (no cache written there)."""
    env = {**os.environ, "PYTHONPATH": str(root)}
    return subprocess.run(
        [sys.executable, "-c", "from importlinter.cli import lint_imports_command; lint_imports_command()",
         "--config", str(root / "pyproject.toml"), "--no-cache"],
        cwd=root, env=env, capture_output=True, text=True, timeout=300)


def test_the_import_contract_holds():
    run = lint_imports(REPO)
    assert run.returncode == 0, f"lint-imports found broken contracts:\n{run.stdout}\n{run.stderr}"
    assert "0 broken" in run.stdout


def test_a_function_level_circle_or_an_upward_import_breaks_it(tmp_path):
    for pkg in ("models", "realtime"):
        shutil.copytree(REPO / pkg, tmp_path / pkg, ignore=shutil.ignore_patterns("__pycache__", "assets"))
    shutil.copy(REPO / "pyproject.toml", tmp_path / "pyproject.toml")
    skeleton = tmp_path / "models" / "rig" / "skeleton.py"  # retarget imports skeleton; now the reverse too
    skeleton.write_text(skeleton.read_text() + "\n\ndef _fit(p):\n    from models.rig.retarget import fit_skeleton\n\n"
                        "    return fit_skeleton(p)\n")
    run = lint_imports(tmp_path)
    assert run.returncode != 0 and "No cycles are allowed in models.rig" in run.stdout, run.stdout
    assert "skeleton -> .retarget" in run.stdout, run.stdout

    skeleton.write_text((REPO / "models" / "rig" / "skeleton.py").read_text())
    generate = tmp_path / "models" / "generate.py"
    generate.write_text(generate.read_text() + "\n\ndef _engine():\n    import realtime.engine\n\n"
                        "    return realtime.engine\n")
    run = lint_imports(tmp_path)
    assert run.returncode != 0 and "models is not allowed to import realtime" in run.stdout, run.stdout
    assert "models.generate -> realtime.engine" in run.stdout, run.stdout

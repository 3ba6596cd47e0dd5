"""`pip install` of the built wheel into a fresh virtual environment gives a working `performer`.

The path for machines without make or apt (docs/install.md, "Without make"): the wheel is
built from this tree, installed into a new venv (no system site-packages, torch first, then
the wheel with constraints.txt) and runs `performer generate` on the bundled clip from
outside the repository, so nothing of the checkout is importable. About 2-4 minutes on the
shared 2-core machine with pip's cache warm (installs pass --no-compile: byte-compiling
torch's files would double the install time); marked slow, run by `make test` and CI.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from models.timebase import FPS

REPO = Path(__file__).resolve().parents[1]
#: What the build reads: the project file, the README it names, the two packages, the built viewer.
BUILD_INPUTS = ("pyproject.toml", "README.md", "realtime", "models", "clients/web/dist")
TORCH = "torch==2.13.0"  # as the Makefile and docs/install.md: the CPU build, installed first


def _run(cmd: list[str], timeout: float, **kw) -> subprocess.CompletedProcess:
    t = time.monotonic()
    res = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=timeout, **kw)
    print(f"{time.monotonic() - t:6.1f} s  {' '.join(map(str, cmd))}")
    assert res.returncode == 0, f"{' '.join(map(str, cmd))} failed ({res.returncode}):\n{res.stdout}\n{res.stderr}"
    return res


def _clean_env() -> dict[str, str]:
    """This environment without what would make the checkout or the project venv importable."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    env["PYTHONNOUSERSITE"] = "1"
    return env


@pytest.mark.slow
def test_wheel_installs_into_a_fresh_venv_and_generates_from_the_bundled_clip(tmp_path):
    src = tmp_path / "src"
    for name in BUILD_INPUTS:
        path = REPO / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info"))
        else:
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, src / name)
    env = _clean_env()
    # Build with this venv's setuptools when it has one (no download); else pip's isolated build.
    isolation = ["--no-build-isolation"] if importlib.util.find_spec("setuptools") else []
    _run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", *isolation, "-w", tmp_path / "dist", src],
         timeout=600, env=env, cwd=tmp_path)
    wheels = list((tmp_path / "dist").glob("live_performer-*.whl"))
    assert len(wheels) == 1, wheels

    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", venv], timeout=300, env=env, cwd=tmp_path)
    bindir = venv / ("Scripts" if os.name == "nt" else "bin")
    pip = [bindir / "python", "-m", "pip", "install", "-q", "--no-compile", "--disable-pip-version-check"]
    _run([*pip, TORCH], timeout=1200, env=env, cwd=tmp_path)
    _run([*pip, "-c", REPO / "constraints.txt", wheels[0]], timeout=1200, env=env, cwd=tmp_path)

    # Everything comes from the venv: the packages, the bundled clip and checkpoint, the viewer.
    probe = _run([bindir / "python", "-c",
                  "import realtime, models.features.audio_io as a, realtime.pipeline as p, realtime.ws_server as w; "
                  "print(realtime.__file__); print(a.bundled_clip_path()); print(p.default_checkpoint_path()); "
                  "print(w.default_static_dir() / 'index.html')"], timeout=300, env=env, cwd=tmp_path)
    package, clip, checkpoint, viewer = (Path(line) for line in probe.stdout.split())
    for path in (package, clip, checkpoint, viewer):
        assert path.resolve().is_relative_to(venv.resolve()), f"{path} is not from the fresh venv"
        assert path.is_file(), f"{path} missing from the installed package"

    out = tmp_path / "clip.bvh"
    res = _run([bindir / "performer", "generate", clip, "--out", out], timeout=900, env=env, cwd=tmp_path)
    print(res.stdout + res.stderr)
    text = out.read_text()
    frames = int(re.search(r"^Frames:\s*(\d+)", text, re.M).group(1))
    seconds = float(re.search(r"from ([\d.]+) s of audio", res.stdout + res.stderr).group(1))
    assert text.startswith("HIERARCHY") and frames == round(seconds * FPS) and frames > 0

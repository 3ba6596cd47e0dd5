"""`pip install` of the built wheel into a fresh virtual environment gives a working `performer`.

The path for machines without make or apt (docs/install.md, "Without make"): the wheel is
built from this tree, installed by pip into a new venv (no system site-packages) and runs
`performer generate` on the bundled clip from outside the repository, so nothing of the
checkout is importable. The wheel's dependencies are not downloaded and unpacked again: the
distributions its metadata requires, and theirs (nothing else), are linked into the new venv
from this environment, which holds them at the versions of constraints.txt, and `pip check`
in the new venv confirms that they meet every requirement the wheel declares. A dependency
the code imports but the wheel does not declare is missing there, as on a user's machine.
Marked slow, run by `make test` and CI.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import zipfile
import time
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from models.timebase import FPS

REPO = Path(__file__).resolve().parents[1]
#: What the build reads: the project file, the README it names, the two packages, the built viewer.
BUILD_INPUTS = ("pyproject.toml", "README.md", "realtime", "models", "clients/web/dist")


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


def _requirements(lines: list[str], extras: frozenset[str] = frozenset()) -> list[Requirement]:
    """Of ``Requires-Dist`` values, those that apply here (markers evaluated, ``extras`` asked)."""
    reqs = [Requirement(line) for line in lines]
    return [r for r in reqs if r.marker is None or any(r.marker.evaluate({"extra": e}) for e in extras | {""})]


def _dependency_closure(wheel: Path) -> list[importlib.metadata.Distribution]:
    """The installed distributions that ``wheel`` requires, directly or through another one."""
    with zipfile.ZipFile(wheel) as z:
        meta = z.read(next(n for n in z.namelist() if n.endswith(".dist-info/METADATA"))).decode()
    requires = [line.split(":", 1)[1].strip() for line in meta.splitlines() if line.startswith("Requires-Dist:")]
    todo, seen, dists = _requirements(requires), set(), []
    while todo:
        req = todo.pop()
        key = canonicalize_name(req.name)
        if (key, frozenset(req.extras)) in seen:
            continue
        seen.add((key, frozenset(req.extras)))
        dist = importlib.metadata.distribution(req.name)  # raises when this environment lacks it
        if all(canonicalize_name(d.metadata["Name"]) != key for d in dists):
            dists.append(dist)
        todo += _requirements(dist.metadata.get_all("Requires-Dist") or [], frozenset(req.extras))
    return dists


def _link_into(dists: list[importlib.metadata.Distribution], site: Path) -> None:
    """Symlink each distribution's top-level files and folders (packages, .libs, dist-info) into ``site``."""
    here = {Path(sysconfig.get_paths()[k]).resolve() for k in ("purelib", "platlib")}
    for dist in dists:
        base = Path(dist.locate_file("")).resolve()
        assert base in here, f"{dist.metadata['Name']} is installed at {base}, not in this environment"
        for top in sorted({f.parts[0] for f in dist.files or [] if f.parts and f.parts[0] not in ("..", "__pycache__")}):
            if not (site / top).exists() and (base / top).exists():
                (site / top).symlink_to(base / top)


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
    _run([sys.executable, "-m", "venv", "--without-pip", venv], timeout=300, env=env, cwd=tmp_path)
    bindir = venv / ("Scripts" if os.name == "nt" else "bin")
    pip = [sys.executable, "-m", "pip", "--python", bindir / "python", "--disable-pip-version-check"]
    _run([*pip, "install", "-q", "--no-compile", "--no-deps", wheels[0]], timeout=600, env=env, cwd=tmp_path)
    site = Path(_run([bindir / "python", "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                     timeout=60, env=env, cwd=tmp_path).stdout.strip())
    deps = _dependency_closure(wheels[0])
    assert {"torch", "numpy", "librosa", "numba"} <= {canonicalize_name(d.metadata["Name"]) for d in deps}
    _link_into(deps, site)
    _run([*pip, "check"], timeout=300, env=env, cwd=tmp_path)  # every requirement of the wheel met, and theirs

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

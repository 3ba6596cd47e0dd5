"""Every benchmarks/ script the docs, the Makefile, the code and the tests name exists, and
benchmarks/studies/README.md lists every study.

The docs quote each figure next to the command that produced it (``benchmarks/X.py`` or
``benchmarks/studies/X.py``); a script moved without its citations would leave a reader
with a command that does not run.
"""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
STUDIES = REPO / "benchmarks" / "studies"


def _texts() -> list[Path]:
    texts = [REPO / "README.md", REPO / "Makefile", *(REPO / "docs").glob("*.md"), *(REPO / "benchmarks").rglob("*.md")]
    for folder in ("realtime", "models", "benchmarks", "tests"):
        texts += (REPO / folder).rglob("*.py")
    return texts


def test_every_cited_benchmark_script_exists() -> None:
    cited: dict[str, Path] = {}
    for path in _texts():
        for name in re.findall(r"(?<![\w/.])benchmarks/[a-z0-9_/]+\.(?:py|sh|toml)", path.read_text(encoding="utf-8")):
            cited.setdefault(name, path.relative_to(REPO))
    assert len(cited) >= 10
    missing = {name: str(where) for name, where in cited.items() if not (REPO / name).is_file()}
    assert not missing, f"cited benchmark scripts that do not exist (path: first file citing it): {missing}"


def test_studies_readme_lists_every_study() -> None:
    table = (STUDIES / "README.md").read_text(encoding="utf-8")
    listed = set(re.findall(r"^\| `([a-z0-9_]+\.py)` \|", table, flags=re.M))
    present = {p.name for p in STUDIES.glob("*.py")}
    assert listed == present, f"studies/README.md lists {sorted(listed - present)} (absent), misses {sorted(present - listed)}"

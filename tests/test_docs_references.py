"""Every reference in README.md and docs/*.md points at something that exists now: a file, a test, a
module's name or constant, a class attribute, a ``performer`` subcommand and its flags, a benchmark
script's flags, a make target, a linked page and heading (tests/_doc_refs.py says how each is read).

The docs quote each figure beside the command that produced it; code moved under them (DanceStream's
chooser and player into chooser.py and player.py, their constants with them) leaves a reader a
command that does not run or a name to look for in the wrong file. 3-5 s on the 2-core machine (`--durations`), no data.
"""

from __future__ import annotations

import functools
from pathlib import Path

from _doc_refs import REPO, Problem, check_doc, docs

# (page, reference): why it is named though it is not in the tree. History names what was removed,
# with the commit that holds it; "pending:" marks a stale reference of a page another change owns.
KNOWN: dict[tuple[str, str], str] = {
    ("docs/data.md", "utils/skel_class.py"): "a file of the Guzheng-Playing repository, not ours",
    ("docs/history-gate.md", "models/networks/host_phrase.py"): "built on branch h10-host, not merged",
    ("docs/history-listening.md", "cold_start.py"): "a study not merged",
    ("docs/history-listening.md", "first_song.py"): "a study not merged",
    ("docs/history-listening.md", "TEMPO_SIZE"): "branch h-quick d4979b6, not shipped",
    ("docs/history-listening.md", "SIZE_HOLD"): "removed: git show ec1abe2:models/networks/size_hold.py",
    ("docs/history-listening.md", "ONSET_TILT"): "tried at c458e0a",
    ("docs/history-listening.md", "SPEED_MATCH_ROOM"): "git show a2f2560",
    ("docs/history.md", "ROOT_LOCK"): "at b9a2be2, removed",
    ("docs/history.md", "SLIP"): "git show eeeb58f:models/networks/feet.py",
    ("docs/history.md", "WARP_QUICK_FLOOR"): "removed: git show ec1abe2:models/networks/member_tables.py",
    ("docs/history.md", "TILT_LOWPASS_HZ"): "removed, at ec1abe2",
    ("docs/stage.md", "WARP_QUICK_FLOOR"): "the jitter_parts table measured at bd4b186; removed at ec1abe2",
    ("docs/stage.md", "tables.WARP_QUICK_FLOOR"): "the jitter_parts table measured at bd4b186; removed at ec1abe2",
    ("docs/stage.md", "TILT_LOWPASS_HZ"): "removed, at ec1abe2",
    ("docs/history-listening.md", "--detector-only"): "not merged: 011b781",
    ("docs/install.md", "--index-url"): "pip's option",
    ("docs/feet.md", "feet.ROOT_LOCK"): "the option at b9a2be2, removed after",
    ("docs/feet.md", "Stage.nudge"): "part of the ROOT_LOCK option at b9a2be2",
}


@functools.cache
def _problems() -> tuple[Problem, ...]:
    return tuple(p for page in docs() for p in check_doc(page))


def test_every_reference_in_the_docs_exists() -> None:
    stale = [str(p) for p in _problems() if (p.doc, p.ref) not in KNOWN]
    assert not stale, "references to nothing in the tree (page:line: reference: why):\n" + "\n".join(stale)


def test_every_known_exception_is_still_named_in_the_docs() -> None:
    found = {(p.doc, p.ref) for p in _problems()}
    gone = [k for k, why in KNOWN.items() if k not in found and not why.startswith("pending:")]
    assert not gone, f"KNOWN names references the docs no longer make (remove them): {gone}"


# One stale reference of each kind (the checker must report its line) and its live counterpart (it must not).
PLANTED = """\
`models/networks/nowhere.py`
`tests/test_chooser.py::test_no_such_behaviour`
`tests/test_chooser.py::test_a_reset_chooser_draws_what_a_fresh_one_draws`, `::test_a_faster_tempo_chooses_quicker_movements`
`models.networks.chooser.NO_SUCH_NAME`
`dance_stream.BEAT_WARP`
`NO_SUCH_CONSTANT_ANYWHERE`
the beat warp's depth (`BEAT_WARP` (models/networks/dance_stream.py))
`DanceStream._tempo_z`
the repeat limit (`dance_stream.py`, `Chooser.draw`)
`performer dance --audio song.wav`
`performer run --no-such-flag`
`performer bench latency --no-such-flag`
`.venv/bin/python benchmarks/hop_profile.py --no-such-flag`
`constants.py models.networks.dance_stream.BEAT_WARP=0 -- benchmarks/listening.py`
`hop_profile.py --seconds 20 --no-such-flag`
[a page](nowhere.md)
[a heading]({repo}/docs/latency.md#no-such-heading)
`make no-such-target`
`no_such_study.py`
`--no-such-option 133`
```sh
nice -n 19 .venv/bin/performer train --config configs/dtm.toml --no-such-flag
```
LIVE
`models/networks/player.py`
`tests/test_chooser.py::test_a_reset_chooser_draws_what_a_fresh_one_draws`, `::test_the_energy_control_draws_calmer_or_livelier_codes`
`models.networks.player.BEAT_WARP`
`player.BEAT_WARP`
`stream.BEAT_WARP`
the beat warp's depth (`BEAT_WARP` (models/networks/player.py))
`Chooser.tempo_z`
the repeat limit (`chooser.py`, `Chooser.draw`)
`performer run --stage 3x2 --facing audience`
`performer bench latency --cores 0,1`
`.venv/bin/python benchmarks/hop_profile.py --seconds 20`
`constants.py models.networks.player.BEAT_WARP=0 -- benchmarks/listening.py --sets stretch`
[a page]({repo}/README.md)
[a heading]({repo}/docs/latency.md#one-performer-the-dancing-default)
`make bench`
`feet.py`
`--lead 133`
```sh
nice -n 19 .venv/bin/performer train --config configs/dtm.toml --data ../shared/data/dwm --out runs/dtm
```
"""


def test_a_planted_stale_reference_of_each_kind_is_caught_and_its_live_twin_is_not(tmp_path: Path) -> None:
    page = tmp_path / "docs" / "planted.md"
    page.parent.mkdir()
    page.write_text(PLANTED.format(repo=REPO), encoding="utf-8")
    lines = PLANTED.splitlines()
    live = lines.index("LIVE") + 1
    flagged = {p.line for p in check_doc(page)}
    stale = {n for n, text in enumerate(lines[:live - 1], 1) if not text.startswith("```")}
    assert stale - flagged == set(), [lines[n - 1] for n in sorted(stale - flagged)]
    assert {n for n in flagged if n > live} == set(), [str(p) for p in check_doc(page) if p.line > live]

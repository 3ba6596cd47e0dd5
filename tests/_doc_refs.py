"""The references README.md and docs/*.md make, checked against the tree (tests/test_docs_references.py).

Kinds: file paths (``models/...py``, ``tests/test_x.py::test_y``, bare ``x.py``), dotted names
(``models.networks.player.BEAT_WARP``, ``realtime/pipeline.build_pipeline``), ``module.CONSTANT`` and
``Class.attr``, bare ``CONSTANTS`` (named somewhere in the code; in the module the text beside them
names), pytest test names, any ``--option`` (some parser or script declares it), command lines
(``performer SUB --flag`` against the real argparse parsers, built in-process by realtime.cli, whose
commands import nothing heavy until they run; ``benchmarks/...py --flag`` against the flags its source
and the sibling scripts it imports declare), make targets, relative links and their heading anchors.
The code is read as text and ast, never imported or run (but for realtime.cli's parser).
Run alone: ``.venv/bin/python tests/_doc_refs.py`` lists every problem.
"""

from __future__ import annotations

import argparse
import ast
import errno
import functools
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from collections.abc import Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CODE_DIRS = ("models", "realtime", "benchmarks", "tests", "clients")
TOP = ("models", "realtime", "tests", "benchmarks", "clients", "configs", "docs")
# `part.CONST` prefixes the studies take for more than one module (jitter_parts.py, amp_parts.py)
ALIASES = {"stream": ("dance_stream", "chooser", "player"), "tables": ("member_tables",)}


@dataclass(frozen=True)
class Problem:
    doc: str
    line: int
    ref: str
    why: str

    def __str__(self) -> str:
        return f"{self.doc}:{self.line}: {self.ref!r}: {self.why}"


# ---------------------------------------------------------------- the tree


SELF = ("_doc_refs.py", "test_docs_references.py")  # they name stale references on purpose
SKIP = ("clients/web/node_modules", ".venv", ".cache", "out/", "runs/", ".git/")


@functools.cache
def tracked() -> tuple[str, ...]:
    """The repository's files (git's list; a tree without git: every file but build outputs)."""
    run = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True)
    if run.returncode == 0 and run.stdout:
        files = run.stdout.splitlines()
    else:
        files = [str(p.relative_to(REPO)) for p in REPO.rglob("*") if p.is_file() and "__pycache__" not in p.parts]
    return tuple(p for p in files if not p.startswith(SKIP) and (REPO / p).is_file())


@functools.cache
def py_files() -> tuple[str, ...]:
    return tuple(p for p in tracked() if p.endswith(".py") and p.split("/")[0] in CODE_DIRS)


@functools.cache
def by_stem() -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for p in py_files():
        out.setdefault(Path(p).stem, []).append(p)
    return out


@functools.cache
def module_tree(path: str) -> ast.Module:
    return ast.parse((REPO / path).read_text(encoding="utf-8"))


def _targets(node: ast.AST, imports: bool = True) -> list[str]:
    """The names a statement binds (with ``imports`` False: not the names it imports)."""
    names = []
    if isinstance(node, ast.Assign):
        for t in node.targets:
            for n in ast.walk(t):
                if isinstance(n, ast.Name):
                    names.append(n.id)
    elif isinstance(node, (ast.AnnAssign, ast.AugAssign)) and isinstance(node.target, ast.Name):
        names.append(node.target.id)
    elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
        names.append(node.name)
    elif isinstance(node, (ast.Import, ast.ImportFrom)) and imports:
        names += [(a.asname or a.name).split(".")[0] for a in node.names]
    return names


def _body_names(body: list[ast.stmt], imports: bool = True) -> set[str]:
    names: set[str] = set()
    for node in body:
        names.update(_targets(node, imports))
        if isinstance(node, (ast.If, ast.Try, ast.With)):  # try/except imports, if TYPE_CHECKING
            for sub in ("body", "orelse", "finalbody", "handlers"):
                for part in getattr(node, sub, []) or []:
                    names |= _body_names(part.body if isinstance(part, ast.ExceptHandler) else [part], imports)
    return names


@functools.cache
def top_names(path: str) -> frozenset[str]:
    return frozenset(_body_names(module_tree(path).body))


@functools.cache
def own_names(path: str) -> frozenset[str]:
    """What a module defines itself (not what it imports): where a constant is set, a class lives."""
    return frozenset(_body_names(module_tree(path).body, imports=False))


@functools.cache
def class_names(path: str, cls: str) -> frozenset[str] | None:
    for node in module_tree(path).body:
        if isinstance(node, ast.ClassDef) and node.name == cls:
            names = _body_names(node.body)
            for n in ast.walk(node):  # self.x = ... anywhere in its methods
                if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id == "self" \
                        and isinstance(n.ctx, ast.Store):
                    names.add(n.attr)
            for n in node.body:  # dataclass / NamedTuple fields
                if isinstance(n, ast.AnnAssign) and isinstance(n.target, ast.Name):
                    names.add(n.target.id)
            return frozenset(names)
    return None


@functools.cache
def defined_at() -> dict[str, tuple[str, ...]]:
    """name -> the py files that define it at module level or in a top-level class body."""
    out: dict[str, list[str]] = {}
    for p in py_files():
        if not p.startswith(("models/", "realtime/", "benchmarks/")):
            continue
        names = set(top_names(p))
        for n in module_tree(p).body:
            if isinstance(n, ast.ClassDef):
                names |= _body_names(n.body)
        for name in names:
            out.setdefault(name, []).append(p)
    return {k: tuple(v) for k, v in out.items()}


def constants_where(name: str) -> tuple[str, ...]:
    """The py files that assign ``name`` at module level or in a class body."""
    return defined_at().get(name, ())


@functools.cache
def code_text() -> str:
    """Every tracked text file but the docs, joined (for names the code spells out anywhere)."""
    texts = []
    for p in tracked():
        if p.startswith("docs/") or p.endswith((".md", ".png", ".gif", ".jpg", ".pt", ".ogg", ".npz", ".wav")) \
                or Path(p).name in SELF:
            continue
        try:
            texts.append((REPO / p).read_text(encoding="utf-8"))
        except (UnicodeDecodeError, FileNotFoundError, IsADirectoryError):
            continue
    return "\n".join(texts)


@functools.cache
def defined_tests() -> dict[str, frozenset[str]]:
    """tests/x.py -> the test function names it defines (module level and in Test classes)."""
    return {p: frozenset(re.findall(r"^\s*(?:async )?def (test_\w+)", (REPO / p).read_text(encoding="utf-8"), re.M))
            for p in py_files() if p.startswith("tests/")}


@functools.cache
def classes() -> dict[str, list[tuple[str, ast.ClassDef]]]:
    out: dict[str, list[tuple[str, ast.ClassDef]]] = {}
    for p in py_files():
        if p.startswith(("models/", "realtime/")):
            for n in module_tree(p).body:
                if isinstance(n, ast.ClassDef):
                    out.setdefault(n.name, []).append((p, n))
    return out


def class_has(cls: str, attr: str, seen: frozenset[str] = frozenset()) -> bool | None:
    """Whether a class of the tree (or a base of it in the tree) has ``attr``; None: no such class."""
    if cls not in classes():
        return None
    for path, node in classes()[cls]:
        names = class_names(path, cls) or frozenset()
        if attr in names:
            return True
        for n in ast.walk(node):  # register_buffer("name", ...)
            if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr.startswith("register_") \
                    and n.args and isinstance(n.args[0], ast.Constant) and n.args[0].value == attr:
                return True
        for b in node.bases:
            bname = b.id if isinstance(b, ast.Name) else b.attr if isinstance(b, ast.Attribute) else None
            if bname and bname not in seen and class_has(bname, attr, seen | {cls}):
                return True
            if bname and bname not in classes():  # a base outside the tree (nn.Module, NamedTuple): unknown
                return True
    return False


def resolve_dotted(parts: list[str], own: bool = False) -> str | None:
    """None when ``a.b.c.Name.attr`` exists (a module path, then names defined in it; with ``own``
    defined there, not imported: what setting it changes), else why not."""
    path = None
    i = 0
    for j in range(len(parts), 0, -1):
        base = "/".join(parts[:j])
        if base + ".py" in py_files():
            path, i = base + ".py", j
            break
        if base + "/__init__.py" in py_files():
            path, i = base + "/__init__.py", j
            break
    if path is None:
        return "no such module"
    rest = parts[i:]
    if not rest:
        return None
    if rest[0] not in (own_names if own else top_names)(path):
        if path.endswith("__init__.py") and any(p.startswith(path[:-11] + rest[0]) for p in py_files()):
            return None
        return f"{path} defines no {rest[0]}"
    if len(rest) > 1:
        names = class_names(path, rest[0])
        if names is not None and rest[1] not in names:
            return f"{path}: class {rest[0]} has no {rest[1]}"
    return None


# ---------------------------------------------------------------- command lines


@functools.cache
def performer_parser() -> argparse.ArgumentParser:
    """``performer``'s parser, as realtime.cli builds it (its commands import nothing heavy to build it)."""
    sys.path.insert(0, str(REPO))
    from realtime.cli import build_parser
    return build_parser()


def _subparsers(parser) -> dict | None:
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            return a.choices
    return None


def _options(parser) -> set[str]:
    return {o for a in parser._actions for o in a.option_strings}


_VISITING: set[str] = set()


@functools.cache
def script_options(path: str) -> frozenset[str]:
    """The option strings a script's argparse calls declare, read from its source (and from the sibling
    scripts it imports, which may build its parser: foot_skating.study_parser); "*" where it parses
    its arguments itself."""
    _VISITING.add(path)
    text = (REPO / path).read_text(encoding="utf-8")
    opts = {"-h", "--help"}
    calls = re.split(r"\.add_argument\(", text)[1:]
    for call in calls:  # each call's leading flag literals; the text up to the next call for its action
        flags = re.findall(r"[\"'](-[\w-]+)[\"']", re.match(r"\s*((?:[\"'][^\"']*[\"']\s*,\s*)*)", call).group(1))
        opts.update(flags)
        if "BooleanOptionalAction" in call:
            opts.update("--no-" + f[2:] for f in flags if f.startswith("--"))
    if len(opts) == 2 and re.search(r"sys\.argv|argv\[", text):
        opts.add("*")
    for mod in re.findall(r"^\s*from (\w+) import", text, re.M):
        sib = str(Path(path).parent / (mod + ".py"))
        if sib in py_files() and sib not in _VISITING:
            opts |= script_options(sib)
    _VISITING.discard(path)
    return frozenset(opts)


@functools.cache
def every_option() -> frozenset[str]:
    """Every option a ``performer`` parser or a script of the tree declares."""
    opts: set[str] = set()
    parsers = [performer_parser()]
    while parsers:
        parser = parsers.pop()
        opts |= _options(parser)
        parsers += list((_subparsers(parser) or {}).values())
    for p in py_files():
        opts |= script_options(p)
    return frozenset(opts)


STOP = {"|", "||", "&&", ";", ">", ">>", "2>&1", "&", "#", "$", "--"}
# words that may stand before a command: `nice -n 19 X`, `taskset -c 0,1 X`, `VAR=1 X`, `python X`
PREFIX = re.compile(r"nice|taskset|time|sudo|-n|-c|\d[\d,]*|[A-Z_]+=\S*|(\S*/)?python3?(\.\d+)?")


def check_command(tokens: list[str]) -> list[str]:
    """Why a tokenised command line names something that does not exist (empty when all is well).
    Only a word at a command's start (after wrappers like nice, env settings, python) is a command."""
    why = []
    i, start = 0, True
    while i < len(tokens):
        t = tokens[i].rstrip(";")
        if t.startswith("#"):
            break
        if t in STOP or tokens[i].endswith(";"):
            i, start = i + 1, True
            continue
        if not start:
            i += 1
            continue
        name = t.rsplit("/", 1)[-1]
        if name == "performer" and i + 1 < len(tokens) and re.fullmatch(r"[a-z]+", tokens[i + 1]):
            i, w = _check_performer(tokens, i + 1)
            why += w
        elif re.fullmatch(r"[\w./-]+\.(py|sh)", t) and (t.startswith("benchmarks/") or name[:-3] in by_stem()):
            i, w = _check_script(tokens, i)
            why += w
        else:
            start = bool(PREFIX.fullmatch(t))
            i += 1
            continue
        start = i < len(tokens) and tokens[i] in STOP
    return why


def _args(tokens: list[str], i: int) -> tuple[list[str], int]:
    j = i
    while j < len(tokens) and tokens[j] not in STOP and not tokens[j].startswith("#"):
        j += 1
    return tokens[i:j], j


def _check_performer(tokens: list[str], i: int) -> tuple[int, list[str]]:
    parser, label = performer_parser(), "performer"
    while (subs := _subparsers(parser)) is not None and i < len(tokens) and re.fullmatch(r"[a-z]+", tokens[i]):
        if tokens[i] not in subs:
            return i + 1, [f"{label} has no subcommand {tokens[i]!r}"]
        parser, label = subs[tokens[i]], f"{label} {tokens[i]}"
        i += 1
    args, j = _args(tokens, i)
    opts = _options(parser)
    return j, [f"{label} has no option {a.split('=')[0]}" for a in args
               if re.fullmatch(r"--?[a-zA-Z][\w-]*(=.*)?", a) and a.split("=")[0] not in opts]


def _check_script(tokens: list[str], i: int) -> tuple[int, list[str]]:
    t = tokens[i]
    cands = [p for p in py_files() if p == t or p.endswith("/" + t)]
    args, j = _args(tokens, i + 1)
    if not cands:  # a .sh script or a missing file: a missing path is reported as a path
        return j, [] if t.endswith(".sh") or t.startswith(TOP) else [f"no file {t}"]
    why = []
    opts = set().union(*(script_options(c) for c in cands))
    if "*" not in opts:
        why += [f"{t} has no option {a.split('=')[0]}" for a in args
                if re.fullmatch(r"--[a-zA-Z][\w-]*(=.*)?", a) and a.split("=")[0] not in opts]
    if Path(t).name == "constants.py":  # MODULE.NAME=VALUE ... -- SCRIPT ARGS
        for a in args:
            if re.fullmatch(r"[\w.]+=.*", a):
                mod, _, name = a.split("=")[0].rpartition(".")
                w = resolve_dotted(mod.split(".") + [name], own=True)
                if w:
                    why.append(f"constants.py {a}: {w}")
    return j, why


# ---------------------------------------------------------------- the docs


def slug(heading: str) -> str:
    h = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip())
    h = re.sub(r"[^\w\- ]", "", h.lower())
    return h.replace(" ", "-")


@functools.cache
def anchors(path: Path) -> frozenset[str]:
    seen: dict[str, int] = {}
    out = set()
    fence = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            fence = not fence
        if fence:
            continue
        out.update(re.findall(r"<a (?:id|name)=\"([^\"]+)\"", line))
        m = re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            s = slug(m.group(1))
            n = seen.get(s, 0)
            out.add(s if n == 0 else f"{s}-{n}")
            seen[s] = n + 1
    return frozenset(out)


PATH_RE = re.compile(r"(?<![\w/.:@-])((?:%s)/[\w.*/-]*[\w*])" % "|".join(TOP))
TEST_RE = re.compile(r"(?<![\w/])((?:tests/)?test_\w+\.py)?::(\w+)(?:::(\w+))?")
DOTTED_RE = re.compile(r"(?<![\w./])((?:models|realtime)(?:\.\w+)+)")
SHORT_RE = re.compile(r"(?<![\w./=])([a-z_][a-z0-9_]*)\.([A-Z][A-Za-z0-9_]*)\b")
CONST_RE = re.compile(r"^[A-Z][A-Z0-9]*(?:_[A-Z0-9]+)+$|^[A-Z]{4,}$")
LINK_RE = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
MAKE_RE = re.compile(r"\bmake ([a-z][\w-]*)")
# `CONST` (models/x/y.py) | `CONST` in `y.py` | `y.py`'s `CONST` | y.py: `CONST`
CLASS_HOME_RE = re.compile(r"`?(?P<m>(?:\w+/)*\w+\.py)`?(?:,|:|'s)? `(?P<c>[A-Z][a-z]\w*)(?:\.\w+)?(?:\([^`]*\))?`")
HOME_RE = re.compile(r"`(?P<c1>[A-Z][A-Z0-9_]+)`,? (?:\(|in |of )`?(?P<m1>[\w/]*\w\.py)\b"
                     r"|`?(?P<m2>[\w/]*\w\.py)`?(?:'s|:) `(?P<c2>[A-Z][A-Z0-9_]+)(?: ?=[^`]*)?`")


def doc_lines(path: Path) -> list[tuple[int, str, bool]]:
    """(line number, text, inside a code fence), continuation lines joined onto their first."""
    out = []
    fence = False
    lines = path.read_text(encoding="utf-8").splitlines()
    k = 0
    while k < len(lines):
        line, start = lines[k], k + 1
        if line.startswith("```"):
            fence = not fence
            k += 1
            continue
        while fence and line.rstrip().endswith("\\") and k + 1 < len(lines):
            k += 1
            line = line.rstrip()[:-1] + " " + lines[k].strip()
        out.append((start, line, fence))
        k += 1
    return out


def _tokens(code: str) -> list[str]:
    try:
        return shlex.split(code, comments=False)
    except ValueError:
        return code.split()


Found = Iterator[tuple[str, str]]  # (reference, why it points at nothing)


def _paths(line: str) -> Found:
    """``models/...``, ``tests/...``, ``benchmarks/...`` paths anywhere in a line (globs, ``path.name`` too)."""
    for m in PATH_RE.finditer(line):
        p = m.group(1).rstrip(".")
        if line[max(0, m.start() - 1)] == ":":  # git show REV:path
            continue
        if "*" in p:
            if not list(REPO.glob(p)):
                yield p, "no file matches"
        elif (REPO / p).exists() or (line[m.end():].startswith("...") and list(REPO.glob(p + "*"))):
            continue
        elif (mm := re.fullmatch(r"((?:\w+/)+\w+)\.(\w+(?:\.\w+)*)", p)) and mm.group(1) + ".py" in py_files():
            if why := resolve_dotted(mm.group(1).split("/") + mm.group(2).split(".")):  # models/generate.run_model
                yield p, why
        elif not Path(p).suffix and list((REPO / p).parent.glob(Path(p).name + ".*")):
            continue  # clients/unreal/PerformerPoseComponent (.h and .cpp)
        else:
            yield p, "no such file or folder"


def _test_ids(line: str) -> Found:
    """``tests/test_x.py::test_y``, ``test_x.py::test_y``, ``::test_y`` (in the file named before it on the
    line, else in some test file), ``test_x.py``."""
    tests = defined_tests()
    last = None
    for m in TEST_RE.finditer(line):
        f, name = m.group(1), m.group(3) or m.group(2)
        if f:
            last = f = f if f.startswith("tests/") else "tests/" + f
        if line[m.end():].startswith(("...", "*")):  # a family: test_nan_guard_...
            if not any(n.startswith(name) for d in tests.values() for n in d):
                yield name + "...", "no test starts so"
        elif last in tests:  # a missing file is reported as a file
            if name not in tests[last]:
                yield f"{last}::{name}", "no such test in that file"
        elif not f and name.startswith("test_") and not any(name in d for d in tests.values()):
            yield f"::{name}", "no such test anywhere"
    for m in re.finditer(r"(?<![\w/])(test_\w+\.py)\b", line):
        if "tests/" + m.group(1) not in tests and not line[:m.start()].endswith("tests/") \
                and not list(REPO.glob("tests/" + m.group(1))):
            yield m.group(1), "no such test file"


def _links(page: Path, line: str) -> Found:
    """Relative links and images: the file, and for a page the heading (or ``<a id>``) of the anchor."""
    for m in LINK_RE.finditer(line):
        target = m.group(1)
        if re.match(r"[a-z]+:", target):
            continue
        file, _, anchor = target.partition("#")
        dest = (page.parent / file).resolve() if file else page
        if not dest.exists():
            yield target, "link to a missing file"
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            yield target, "no such heading"


def _names(span: str) -> Found:
    """The names in one code span: tests, dotted names, ``module.CONST``, bare files, ``Class.attr``, CONSTANTS."""
    for m in re.finditer(r"(?<![\w:/.])(test_[a-z0-9_]{12,})(?![\w.])", span):
        if not any(m.group(1) in d for d in defined_tests().values()):
            yield m.group(1), "no such test anywhere"
    for m in DOTTED_RE.finditer(span):
        if why := resolve_dotted(m.group(1).split(".")):
            yield m.group(1), why
    for m in SHORT_RE.finditer(span):
        mod, name = m.group(1), m.group(2)
        files = [p for s in ALIASES.get(mod, (mod,)) for p in by_stem().get(s, []) if not p.startswith("tests/")]
        if files and not any(name in own_names(p) for p in files):
            yield f"{mod}.{name}", f"not defined in {', '.join(files)}"
    for m in re.finditer(r"(?<![\w/.:-])((?:[a-z_]+/)*[a-z_]\w*\.py)\b", span):
        f = m.group(1)
        if not f.startswith(TOP) and not any(p == f or p.endswith("/" + f) for p in tracked()):
            yield f, "no such file in the tree"
    for m in re.finditer(r"(?<![\w.])([A-Z][a-z]\w*)(?:\([^()]*\))?\.([a-z_]\w*)\b", span):
        if class_has(m.group(1), m.group(2)) is False:
            yield f"{m.group(1)}.{m.group(2)}", "no such attribute of the class"
    name = span.strip()
    if CONST_RE.fullmatch(name) and not constants_where(name) and name not in code_text() \
            and not hasattr(errno, name):
        yield name, "named nowhere in the code"


def _module_files(mod: str) -> list[str]:
    """models/ and realtime/ files a ``y.py`` or ``models/x/y.py`` of the docs may mean."""
    return [p for p in by_stem().get(Path(mod).stem, []) if p.startswith(("models/", "realtime/"))
            and (p == mod or p.endswith("/" + mod))]


def _homes(line: str) -> Found:
    """A CONSTANT or class the text beside it says lives in a module (``CONST`` (y.py), ``y.py``'s ``CONST``,
    ``y.py``, ``Class.method``): there."""
    for m in CLASS_HOME_RE.finditer(line):
        files = _module_files(m.group("m"))
        if files and not any(m.group("c") in own_names(p) for p in files):
            yield f"{m.group('m')}, {m.group('c')}", "the class is not defined there"
    for m in HOME_RE.finditer(line):
        name, mod = m.group("c1") or m.group("c2"), m.group("m1") or m.group("m2")
        files = _module_files(mod)
        if files and CONST_RE.fullmatch(name) and not any(name in own_names(p) for p in files):
            yield f"{name} in {mod}", "lives in " + (", ".join(constants_where(name)) or "no module")


def _commands(span: str) -> Found:
    """Options alone (``--lead 133``), command lines and make targets of one code span (or fenced line)."""
    for m in re.finditer(r"(?<![\w-])(--[a-z][\w-]+)", span):
        if m.group(1) not in every_option() and m.group(1) not in code_text():
            yield m.group(1), "no parser or script of the tree has this option"
    for why in check_command(_tokens(span)):
        yield (span if len(span) < 120 else span[:117] + "..."), why
    for m in MAKE_RE.finditer(span):
        if not re.search(rf"^{re.escape(m.group(1))}:", makefile(), flags=re.M):
            yield f"make {m.group(1)}", "no such make target"


@functools.cache
def makefile() -> str:
    return (REPO / "Makefile").read_text(encoding="utf-8")


def check_doc(page: Path) -> list[Problem]:
    """The references of one markdown page that point at nothing (``page`` may lie outside the tree)."""
    rel = str(page.relative_to(REPO)) if page.is_relative_to(REPO) else str(page)
    probs: list[Problem] = []
    for no, line, fence in doc_lines(page):
        spans = [line] if fence else re.findall(r"`([^`]+)`", line)
        found = [*_paths(line), *_test_ids(line)]
        if not fence:
            found += [*_links(page, line), *_homes(line)]
        for span in spans:
            found += [*_names(span), *_commands(span)]
        probs += [Problem(rel, no, ref, why) for ref, why in found]
    return probs


def docs() -> list[Path]:
    """The pages checked: README.md and docs/*.md."""
    return [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


def main() -> int:
    probs = [p for d in docs() for p in check_doc(d)]
    for p in probs:
        print(p)
    print(f"{len(probs)} problems in {len(docs())} pages")
    return 1 if probs else 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The manual: every citation of docs/physics.md resolves, the README stays short.

A citation is a section (``docs/physics.md §3.3``, ``§9``, ``section 4``, ``§10-10.3``),
an equation label (``[Eq. 22]``, ``Eq. 9``), a check (``C5``, ``C1-C14``) or a numbered
item of a section (``§5.2, step 3``, ``§3.2, limit 2``), in the code (``simulator/``,
``patterns/``) and in the rest of the repository's text (tests, benchmarks, validation,
examples, notebooks, the manual's pages). Each must exist in docs/physics.md: a heading
``## §N ...``, an equation label ``[Eq. N]`` (in the cited section when one is named), a
row ``| CN |`` of the checks table, a list item ``N.`` of the section. The site build
itself (``mkdocs build --strict``, run by ``make test`` and ``make docs``) fails on a
broken link between the pages.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PHYSICS = ROOT / "docs" / "physics.md"

#: Where citations are looked for: the code first, then every other text the project keeps.
CODE_DIRS = ("simulator", "patterns")
TEXT_DIRS = ("tests", "benchmarks", "validation", "examples", "notebooks", "docs")
SUFFIXES = {".py", ".pyi", ".md", ".toml", ".ipynb", ".txt"}


# ----------------------------------------------------------------------- the physics page
@dataclass(frozen=True)
class Section:
    number: str  # "3.3"
    start: int  # line index of the heading
    end: int  # line index of the next heading that is not a subsection (exclusive)
    body_end: int  # line index of the next heading of any level (exclusive)


def _sections(lines: list[str]) -> dict[str, Section]:
    heads = [
        (i, m.group(1))
        for i, line in enumerate(lines)
        if (m := re.match(r"#{2,4} §(\d+(?:\.\d+)*)\b", line))
    ]
    out = {}
    for k, (i, num) in enumerate(heads):
        end = next((j for j, n in heads[k + 1 :] if not n.startswith(num + ".")), len(lines))
        body_end = heads[k + 1][0] if k + 1 < len(heads) else len(lines)
        out[num] = Section(num, i, end, body_end)
    return out


PAGE = PHYSICS.read_text(encoding="utf-8").splitlines()
SECTIONS = _sections(PAGE)
EQUATIONS = {
    int(n): i for i, line in enumerate(PAGE) for n in re.findall(r"\[Eqs?\. (\d+)\]", line)
}
CHECKS = {int(m.group(1)) for line in PAGE if (m := re.match(r"\| C(\d+) \|", line))}


def _numbered_items(section: Section) -> set[int]:
    return {
        int(m.group(1))
        for line in PAGE[section.start + 1 : section.body_end]
        if (m := re.match(r"\s*(\d+)\. ", line))
    }


# ------------------------------------------------------------------------ finding citations
_SEC = r"§\s?(?P<sec>\d+(?:\.\d+)*)|\bsections?\s+(?P<sec2>\d+(?:\.\d+)*)"
_TOKEN = re.compile(
    rf"(?:{_SEC}"
    r"|\bEqs?\.\s?(?P<eq>\d+)"
    r"|\bC(?P<check>\d{1,2})\b"
    r"|\b(?P<kind>step|limit|condition|item)s?\s+\(?(?P<item>\d+)\)?"
    r"|(?P<bare>\d+(?:\.\d+)*)(?![\w.]*\s?(?:um|nm|nl|deg|px|%|mN|N/m|µm|°)))"
)
_SEP = re.compile(r"(?:\s*(?:,|;|/|-|–|—|\band\b|\bor\b|\[|\])\s*)*\s*")
_ANCHOR = re.compile(r"physics\.md|§|\bsections?\s+(?=\d)|\(C\d{1,2}\b|\bchecks?\s+C\d")


@dataclass(frozen=True)
class Citation:
    where: str  # file:line
    text: str  # the chain as written
    refs: tuple  # ("sec", "3.3") | ("eq", 9, section or None) | ("check", 5) | ("item", "limit", 2, section)


def _chain(text: str, pos: int) -> tuple[list[tuple], int]:
    """Tokens of one citation chain starting at ``pos`` (just after ``physics.md``, or at a
    ``§``/``section``/``(C``), up to the first word that is no reference."""
    refs: list[tuple] = []
    section = None
    while True:
        m = _SEP.match(text, pos)
        assert m is not None  # _SEP matches the empty string
        sep_end = m.end()
        t = _TOKEN.match(text, sep_end)
        if not t or t.end() == sep_end:
            break
        g = t.groupdict()
        if g["sec"] or g["sec2"]:
            section = g["sec"] or g["sec2"]
            refs.append(("sec", section))
        elif g["eq"]:
            refs.append(("eq", int(g["eq"]), section))
        elif g["check"]:
            refs.append(("check", int(g["check"])))
        elif g["item"]:
            if section is None:
                break
            refs.append(("item", g["kind"], int(g["item"]), section))
        elif g["bare"]:
            # a bare number continues a list of sections: "§10-10.3", "§6 and 10"
            if (
                not refs
                or refs[-1][0] != "sec"
                or text[pos:sep_end].strip() not in {"-", "–", ",", "and"}
            ):
                break
            section = g["bare"]
            refs.append(("sec", section))
        pos = t.end()
    return refs, pos


def _text_files(dirs) -> list[Path]:
    files = []
    for d in dirs:
        files += [
            p
            for p in sorted((ROOT / d).rglob("*"))
            if p.suffix in SUFFIXES
            and p.is_file()
            and ".ipynb_checkpoints" not in p.parts
            and "__pycache__" not in p.parts
        ]
    return files


def citations_in(where: str, text: str) -> list[Citation]:
    out = []
    pos = 0
    while m := _ANCHOR.search(text, pos):
        if text.startswith("physics.md", m.start()):
            start = m.end()
        elif text.startswith("(C", m.start()):
            start = m.start() + 1
        elif text.startswith("check", m.start()):
            start = m.end() - 2
        else:
            start = m.start()
        refs, end = _chain(text, start)
        if refs:
            line = text.count("\n", 0, m.start()) + 1
            out.append(
                Citation(f"{where}:{line}", text[m.start() : end].replace("\n", " "), tuple(refs))
            )
        pos = max(end, m.end())
    return out


def citations(files: list[Path]) -> list[Citation]:
    return [
        c
        for p in files
        for c in citations_in(
            str(p.relative_to(ROOT)), p.read_text(encoding="utf-8", errors="replace")
        )
    ]


def _unresolved(cites: list[Citation]) -> list[str]:
    bad = []
    for c in cites:
        for ref in c.refs:
            kind = ref[0]
            if kind == "sec" and ref[1] not in SECTIONS:
                bad.append(f"{c.where}: {c.text!r}: no heading §{ref[1]}")
            elif kind == "eq":
                _, n, sec = ref
                if n not in EQUATIONS:
                    bad.append(f"{c.where}: {c.text!r}: no equation label [Eq. {n}]")
                elif sec in SECTIONS and not (
                    SECTIONS[sec].start <= EQUATIONS[n] < SECTIONS[sec].end
                ):
                    bad.append(f"{c.where}: {c.text!r}: [Eq. {n}] is not in §{sec}")
            elif kind == "check" and ref[1] not in CHECKS:
                bad.append(f"{c.where}: {c.text!r}: no check C{ref[1]}")
            elif kind == "item":
                _, what, n, sec = ref
                if sec in SECTIONS and n not in _numbered_items(SECTIONS[sec]):
                    bad.append(f"{c.where}: {c.text!r}: §{sec} has no numbered {what} {n}")
    return bad


# -------------------------------------------------------------------------------- tests
def test_the_physics_page_is_numbered():
    assert {"1", "2", "3.2", "3.3", "4", "5.2", "6.3", "9", "10", "11", "12"} <= set(SECTIONS)
    assert CHECKS == set(range(1, 15))
    # the section numbers follow each other: no gaps, no repeats
    tops = [int(n) for n in SECTIONS if "." not in n]
    assert tops == list(range(1, len(tops) + 1))
    for top in tops:
        subs = [
            int(n.split(".")[1])
            for n in SECTIONS
            if n.count(".") == 1 and n.split(".")[0] == str(top)
        ]
        assert subs == list(range(1, len(subs) + 1)), (top, subs)


def test_the_citation_finder_reads_every_form():
    cases = {
        "(docs/physics.md §3.2, Eq. 9).": [("sec", "3.2"), ("eq", 9, "3.2")],
        "docs/physics.md §9 [Eq. 23] and C12 (h 12.5 um": [
            ("sec", "9"),
            ("eq", 23, "9"),
            ("check", 12),
        ],
        "(docs/physics.md §10-10.3) are built": [("sec", "10"), ("sec", "10.3")],
        "docs/physics.md section 11) a 1-D model": [("sec", "11")],
        "(docs/physics.md §5.2, step 3).": [("sec", "5.2"), ("item", "step", 3, "5.2")],
        "docs/physics.md C1, C5, C6, C9, C11), raster": [("check", n) for n in (1, 5, 6, 9, 11)],
        "spring (C13);": [("check", 13)],
        "analytic check listed there (C1–C14) is": [("check", 1), ("check", 14)],
        "(docs/physics.md §7–§9:": [("sec", "7"), ("sec", "9")],
        "B-splines are C1 (no kinks": [],
        "(docs/physics.md §7), 20 nl": [("sec", "7")],
    }
    for text, want in cases.items():
        got = [r for c in citations_in("case", text) for r in c.refs]
        assert got == want, (text, got)


def test_every_citation_in_the_code_resolves():
    cites = citations(_text_files(CODE_DIRS))
    assert len(cites) > 80  # the code cites the page often; a finder that finds none is broken
    cited = {r[1] for c in cites for r in c.refs if r[0] == "eq"}
    assert {6, 9, 10, 17, 22, 23} <= cited
    assert not _unresolved(cites), "\n".join(_unresolved(cites))


def test_every_citation_elsewhere_resolves():
    files = _text_files(TEXT_DIRS) + [ROOT / "README.md"]
    files = [p for p in files if p.name != "test_docs.py"]
    cites = citations(files)
    assert len(cites) > 50
    assert not _unresolved(cites), "\n".join(_unresolved(cites))


def test_no_citation_of_the_external_reference():
    """The code and the pages cite docs/physics.md, never the working notes it was written from."""
    pattern = re.compile(r"(?<![\"'])PHYSICS(?:\.md|\s+\d|\s+check)|DESIGN\.md|STYLE\.md")
    files = _text_files(CODE_DIRS + TEXT_DIRS) + [
        ROOT / "README.md",
        ROOT / "Makefile",
        ROOT / "mkdocs.yml",
    ]
    hits = [
        f"{p.relative_to(ROOT)}:{i}: {line.strip()}"
        for p in files
        if p.exists() and p.name != "test_docs.py"
        for i, line in enumerate(p.read_text(encoding="utf-8", errors="replace").splitlines(), 1)
        if pattern.search(line)
    ]
    assert not hits, "\n".join(hits)


def test_pages_the_code_names_exist():
    named = set()
    for p in _text_files(CODE_DIRS):
        named |= set(
            re.findall(r"\bdocs/[\w/.-]+?\.(?:md|png|gif)\b", p.read_text(encoding="utf-8"))
        )
    assert "docs/physics.md" in named
    missing = sorted(n for n in named if not (ROOT / n).exists())
    assert not missing, missing


def test_the_readme_is_short_and_starts_with_the_two_commands():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) < 200
    commands = re.findall(r"^(make \w+)", text, re.M)
    assert commands[:2] == ["make demo", "make test"]
    # the demo, and the design example's capture maps
    assert len(re.findall(r"!\[[^\]]*\]\(", text)) == 2
    links = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    assert "docs/physics.md" in links and "docs/benchmarks.md" in links
    missing = [link for link in links if "://" not in link and not (ROOT / link).exists()]
    assert not missing, missing


def _hooks():
    import importlib.util

    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "hooks.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_benchmark_tables_come_from_the_results_files():
    import json

    hooks = _hooks()
    markers = {
        m.group(1)
        for p in (ROOT / "docs").rglob("*.md")
        for m in hooks.MARKER.finditer(p.read_text(encoding="utf-8"))
    }
    assert markers == set(hooks.TABLES)  # every table is shown, and every marker has a table
    landscape = hooks.render("landscape")
    for r in json.loads((ROOT / "benchmarks/results/landscape.json").read_text())["rows"]:
        assert (
            f"| {r['N']} | {hooks.LANDSCAPE_METHODS[r['method']]} | {r['twists']} | {hooks._g(r['seconds'])}"
            in landscape
        )
    sweep = json.loads((ROOT / "benchmarks/results/sweep.json").read_text())
    assert (
        f"| {sweep['loop']['seconds']:.1f} | {sweep['loop']['points_per_s']:.2f} |"
        in hooks.render("sweep")
    )
    accuracy = json.loads((ROOT / "benchmarks/results/accuracy.json").read_text())
    base = next(r for r in accuracy["rows"] if r["knob"] == "baseline")
    assert (
        f"{hooks._acc(base['energy_rms_pct'])} / {hooks._acc(base['force_p90_pct'])} / {hooks._acc(base['landscape_s'])}"
        in hooks.render("accuracy")
    )
    assert "| knob | value | energy RMS %" in hooks.render("accuracy-details")
    design = json.loads((ROOT / "benchmarks/results/design_freeform.json").read_text())
    for r in design["rows"]:
        assert f"| {hooks._g(r['seconds_per_iteration'] * 1e3)} |" in hooks.render(
            "design-freeform"
        )


def test_every_package_has_its_api_page():
    """One API page per package face, in the site's navigation, showing the face's ``__all__``."""
    import importlib

    hooks = _hooks()
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    packages = sorted(
        p.name for p in (ROOT / "simulator").iterdir() if (p / "__init__.pyi").exists()
    )
    assert {
        "core",
        "scene",
        "physics",
        "liquid",
        "landscape",
        "motion",
        "batch",
        "sweep",
        "render",
        "testing",
    } <= set(packages)
    for name in packages:
        page = ROOT / "docs" / "api" / f"{name}.md"
        assert f"::: simulator.{name}\n" in page.read_text(encoding="utf-8"), page
        assert f"api/{name}.md" in nav, name
        assert sorted(hooks.face_names(f"simulator.{name}")) == sorted(
            importlib.import_module(f"simulator.{name}").__all__
        )

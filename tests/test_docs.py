"""The package's text stays a reference, not a lab notebook, and the README stays a front door.

Docstrings and comments state decisions, units and sources.  A date there is a measurement
log that belongs in CHANGELOG.md, and a README section named there breaks when the README is
reorganised: each is refused here, with the file and line, so a reader of the code is sent to
a docs page or given the reason itself.  The docs site's own checks (every page builds, every
link and image of the built site resolves) run in ``make docs`` (docs/_ext/site_check.py).
"""
from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# the package, the shipped configuration files and the repository's scripts; not the trained
# agents' run records (config.yml, evaluations.csv), which are data
PACKAGE_TEXT = sorted([*(REPO / "abb_gym").rglob("*.py"), *(REPO / "configs").rglob("*.yaml"),
                       *(REPO / "configs").rglob("*.yml"), *(REPO / "agents").glob("*.py")])
# 2026-11-24, 2026-11-23/24, "24 November 2026", "November 2026"
DATE = re.compile(r"\b(19|20)\d\d-[01]\d-[0-3]\d\b|\b([0-3]?\d )?(January|February|March|April|"
                  r"May|June|July|August|September|October|November|December),? (19|20)\d\d\b")
README = re.compile(r"README")
# the modules that write a Markdown file's marked sections on request (agents/evaluate.py
# --readme): they name README files as what they write, not as a source
WRITES_READMES = {REPO / "abb_gym" / "evaluation" / "results_pages.py",
                  REPO / "agents" / "evaluate.py"}
# a README section cited by its title: README "Title", README, "Title", the README's "Title"
README_SECTION = re.compile(r"README(\.md)?('s)?,?\s*[\"'][A-Z]")


def _hits(pattern: re.Pattern, paths) -> list[str]:
    return [f"{path.relative_to(REPO)}:{n}: {line.strip()}"
            for path in paths for n, line in enumerate(path.read_text().splitlines(), 1)
            if pattern.search(line)]


def test_the_patterns_catch_what_they_are_for():
    assert DATE.search("measured on 2026-11-24 at 1024") and DATE.search("(2026-11-23/24)")
    assert DATE.search("a profile of 24 November 2026") and DATE.search("in November 2026")
    assert not DATE.search("Yoshida 2014, eq. 2-9; Spannan 2021 Table 6.4; 1e-12 m")
    assert README.search('(README, "Blocks of 128 lanes")')
    for cited in ('README "Compiled kernels"', 'README, "Two vectors"', "README.md, 'Lanes'",
                  'the README\'s "Blocks of 128 lanes"'):
        assert README_SECTION.search(cited), cited
    assert not README_SECTION.search("regenerates agents/README.md (the tables)")
    assert not README_SECTION.search('REPO / "README.md"; inside a README\'s chapter')


def test_package_files_carry_no_dates():
    assert PACKAGE_TEXT and _hits(DATE, PACKAGE_TEXT) == []


def test_package_files_cite_no_readme():
    # a README section as a reference breaks when the README changes: name a docs page
    # (docs/...) or give the reason itself
    assert _hits(README, [p for p in PACKAGE_TEXT if p not in WRITES_READMES]) == []
    assert _hits(README_SECTION, PACKAGE_TEXT) == []


def test_readme_is_a_front_door():
    lines = (REPO / "README.md").read_text().splitlines()
    assert len(lines) <= 250, f"README.md has {len(lines)} lines; the details go to docs/"
    assert _hits(DATE, [REPO / "README.md"]) == []


def test_readme_lists_every_environment_id_and_links_existing_docs():
    from abb_gym.envs import ENV_IDS
    text = (REPO / "README.md").read_text()
    table = [line for line in text.splitlines() if line.startswith("| `abb_gym/")]
    assert [line.split("`")[1] for line in table] == list(ENV_IDS)
    links = re.findall(r"\]\(((?:docs|agents)/[^)#]+)", text)
    assert links and [link for link in links if not (REPO / link).exists()] == []


def test_every_shipped_agent_has_a_results_page_in_the_index():
    # agents/evaluate.py writes docs/results/<agent>.md and the index linking them; an agent
    # shipped without its evaluation would be missing here
    results = REPO / "docs" / "results"
    index = (results / "index.md").read_text()
    agents = sorted(p.name for p in (REPO / "agents" / "trained").iterdir()
                    if (p / "agent.yml").is_file())
    assert agents
    for name in agents:
        assert (results / f"{name}.md").is_file(), f"no results page for {name}"
        assert f"]({name}.md)" in index, f"docs/results/index.md does not link {name}"


def test_the_site_check_finds_missing_files_and_anchors(tmp_path):
    # docs/_ext/site_check.py fails `make docs` on these (a Sphinx extension, loaded by path)
    import importlib.util
    spec = importlib.util.spec_from_file_location("site_check",
                                                  REPO / "docs" / "_ext" / "site_check.py")
    site_check = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(site_check)
    (tmp_path / "img").mkdir()
    (tmp_path / "img" / "a.png").write_bytes(b"png")
    (tmp_path / "b.html").write_text('<h1 id="top">B</h1>')
    (tmp_path / "a.html").write_text(
        '<a href="b.html#top">ok</a><img src="img/a.png"><a href="https://x.org/y">out</a>'
        '<a href="c.html">missing</a><img src="img/none.png"><a href="b.html#nowhere">x</a>')
    problems = site_check.broken_links(tmp_path)
    assert len(problems) == 3, problems
    assert any("c.html" in p for p in problems) and any("none.png" in p for p in problems)
    assert any("#nowhere" in p for p in problems)

"""After an HTML build, every local link and image of the site must resolve (a Sphinx extension).

Sphinx warns about a missing image or an unknown document it was asked to resolve, but not
about a raw link in a page (``<a href="x.html">``, a Markdown link to a file outside the
docs) or a generated page that points nowhere.  This reads every built page and warns, so that
``make docs`` (``-W``) fails, for each ``href`` or ``src`` that names a file the site does not
have or an anchor the target page does not define.  Links to other sites are not fetched (the
build runs offline).
"""
from __future__ import annotations

import re
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit


class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links: list[tuple[str, str]] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if "id" in attrs:
            self.ids.add(attrs["id"])
        for key in ("href", "src"):
            if attrs.get(key) and not (tag == "link" and key == "href"
                                       and attrs.get("rel") in ("canonical",)):
                self.links.append((tag, attrs[key]))


def _parse(path: Path) -> _Links:
    parser = _Links()
    parser.feed(path.read_text(errors="replace"))
    return parser


def broken_links(outdir: Path, built: list[Path] | None = None) -> list[str]:
    """``page: link`` for every local link of the built pages (default: every page in
    ``outdir``) that resolves to nothing."""
    pages = {p: _parse(p) for p in (built if built is not None else outdir.rglob("*.html"))}
    problems = []
    for page, parsed in pages.items():
        for tag, link in parsed.links:
            parts = urlsplit(link)
            if parts.scheme or link.startswith(("//", "mailto:", "javascript:", "data:")):
                continue
            target = (page.parent / unquote(parts.path)).resolve() if parts.path else page
            if parts.path and not target.exists():
                problems.append(f"{page.relative_to(outdir)}: <{tag}> {link} (no such file)")
                continue
            if parts.fragment and target.suffix == ".html" and target.is_file():
                ids = pages[target].ids if target in pages else _parse(target).ids
                if unquote(parts.fragment) not in ids:
                    problems.append(f"{page.relative_to(outdir)}: <{tag}> {link} "
                                    f"(no anchor #{parts.fragment})")
    return problems


_SKIP = re.compile(r"^(_static|_sources|_modules)/")


def check(app, exception):
    from sphinx.util import logging   # here, so that broken_links works without Sphinx
    logger = logging.getLogger(__name__)
    if exception is not None or app.builder.format != "html":
        return
    outdir = Path(app.outdir)
    # the pages of this build (a page moved or removed since an earlier build leaves its old
    # file behind, which is not part of the site)
    built = [outdir / app.builder.get_target_uri(doc) for doc in sorted(app.env.found_docs)]
    built += [p for p in outdir.glob("*.html") if p.stem in ("genindex", "py-modindex", "search")]
    for problem in broken_links(outdir, [p for p in built if p.is_file()]):
        if not _SKIP.match(problem):
            logger.warning("broken link: %s", problem, type="site", subtype="link")


def setup(app):
    app.connect("build-finished", check)
    return {"parallel_read_safe": True, "parallel_write_safe": True}

"""How the API reference reads the package's docstrings (a Sphinx extension).

The docstrings are reStructuredText with two exceptions, handled here rather than rewritten:

* absolute values and norms written ``|x|``, as in the papers they cite: reStructuredText
  would take them for substitution references, so they are escaped (outside literals);
* the environment classes, whose docstrings are the Gymnasium-style Markdown of their module
  (sections and pipe tables, also what ``help(env)`` shows): the reference keeps their first
  paragraph and links the environment page, which renders the full text;
* the command modules (``abb_gym.cli.*``), whose docstrings are also their ``--help`` text:
  an indented block there is an example command, shown as a literal block;
* a method that inherits its docstring from a class outside the package (Gymnasium's
  ``Env.step``) names that method instead of parsing a docstring written for other tools;
* NumPy-style ``Parameters`` entries written ``name : description`` (rather than ``name :
  type``) get their description on the next line, before napoleon reads the section, so
  that it is not shown as a type.
"""
from __future__ import annotations

import re

# |x| with no space inside its bars, not ``|x|`` in a literal, not a table rule
_ABS = re.compile(r"(?<![\\|`\w])\|(?=[^\s|])([^|\n]*?[^\s|\\])\|(?![|\w`])")
_LITERAL = re.compile(r"(``.+?``)")


def escape_bars(line: str) -> str:
    """``line`` with each ``|x|`` outside inline literals written ``\\|x\\|``."""
    if line.lstrip().startswith(("|", "+-", "+=")):   # a line block or a grid table
        return line
    parts = _LITERAL.split(line)
    return "".join(p if p.startswith("``") else _ABS.sub(r"\\|\1\\|", p) for p in parts)


def literal_blocks(lines: list[str]) -> list[str]:
    """``lines`` with every indented block that follows a blank line after unindented text
    made a literal block (a ``::`` paragraph before it)."""
    out: list[str] = []
    for i, line in enumerate(lines):
        opens = (i >= 2 and line.startswith(" ") and line.strip() and not lines[i - 1].strip()
                 and lines[i - 2].strip() and not lines[i - 2].startswith(" ")
                 and not lines[i - 2].rstrip().endswith("::"))
        if opens:
            out += ["::", ""]
        out.append(line)
    return out


_SECTION = ("Parameters", "Other Parameters", "Attributes")
_TYPE_LIKE = re.compile(r"^[\w.]+( or [\w.]+)*$")


def numpy_descriptions(lines: list[str]) -> list[str]:
    """``lines`` with each ``name : text`` entry of a NumPy-style parameter section whose text
    is not a type (a type is a dotted name, or several joined by "or") written as ``name``
    and the text indented below it."""
    out: list[str] = []
    section_indent = None
    for i, line in enumerate(lines):
        stripped = line.strip()
        indent = len(line) - len(line.lstrip())
        nxt = lines[i + 1].strip() if i + 1 < len(lines) else ""
        if stripped in _SECTION and nxt and set(nxt) == {"-"}:
            section_indent = indent
        elif section_indent is not None and stripped and indent < section_indent:
            section_indent = None
        elif section_indent is not None and indent == section_indent and " : " in stripped \
                and not set(stripped) <= {"-"}:
            name, text = stripped.split(" : ", 1)
            if not _TYPE_LIKE.match(text.strip()):
                out += [line[:indent] + name, line[:indent] + "    " + text]
                continue
        elif section_indent is not None and stripped and indent == section_indent \
                and " : " not in stripped and not set(stripped) <= {"-"} \
                and lines[i - 1].strip() == "":
            section_indent = None   # a paragraph after the section
        out.append(line)
    return out


def inherited_from_elsewhere(name: str, obj) -> str | None:
    """The dotted name of the method outside abb_gym whose docstring ``obj`` inherits."""
    if getattr(obj, "__doc__", "") is not None or "." not in name:
        return None
    owner_name, attr = name.rsplit(".", 1)
    module_name, _, qual = owner_name.rpartition(".")
    import importlib
    try:
        owner = getattr(importlib.import_module(module_name), qual)
    except (ImportError, AttributeError):
        return None
    for base in getattr(owner, "__mro__", ())[1:]:
        doc = getattr(base.__dict__.get(attr), "__doc__", None)
        if doc:
            return None if base.__module__.startswith("abb_gym") else \
                f"{base.__module__}.{base.__qualname__}.{attr}"
    return None


def env_pages() -> dict[str, str]:
    """Environment module -> the docs page of its id (from the task registry)."""
    from abb_gym_pages import env_docname, tasks
    return {t.module.__name__: env_docname(t.env_id) for t in tasks()}


def process_docstring(app, what, name, obj, options, lines):
    module = getattr(obj, "__module__", None) if what == "class" else name
    markdown = next((i for i, line in enumerate(lines) if line.startswith("## ")), None)
    if markdown is not None:
        page = env_pages().get(module)
        del lines[markdown:]
        if page is not None:
            lines += ["", f"Observation, action, reward, episode end and presets: "
                          f":doc:`/{page}`.", ""]
        else:
            lines += ["", "Observation, reward, episode end and arguments of every "
                          "environment: :doc:`/environments/index`.", ""]
        return
    if what in ("method", "attribute", "property"):
        origin = inherited_from_elsewhere(name, obj)
        if origin is not None:
            lines[:] = [f"As ``{origin}`` (its docstring is inherited).", ""]
            return
    if what == "module" and name.startswith("abb_gym.cli."):
        lines[:] = literal_blocks(lines)
    lines[:] = [escape_bars(line) for line in lines]


def before_napoleon(app, what, name, obj, options, lines):
    lines[:] = numpy_descriptions(lines)


def setup(app):
    # napoleon reads the sections at the default priority (500): this runs first
    app.connect("autodoc-process-docstring", before_napoleon, priority=100)
    app.connect("autodoc-process-docstring", process_docstring)
    return {"parallel_read_safe": True, "parallel_write_safe": True}

"""Pages generated from the package when the docs are built (a Sphinx extension).

One page per environment id (``environments/<id>.md``), the preset and scene references and
the literature checks are written from the code, so that they cannot drift from it:

* :func:`tasks` lists the environments from the task registry (``abb_gym.envs.tasks``: one
  row per id with its action model, classes, default scene and preset), so a task registered
  there gets its page with nothing to add here.
* The text of an environment page is its module's docstring (Description, Action Space,
  Episode length) and ``abb_gym.envs.base.COMMON_DOC`` (Observation Space, Rewards, Starting
  State, Episode End, Info, Arguments, Bad input), converted from their Markdown-with-roles to
  MyST.  The tables of observation entries, episode lengths and presets are computed with
  ``abb_gym.envs.setup.EnvSetup`` and :func:`abb_gym.envs.episode_steps`, exactly as
  ``gym.make`` would build the environment.
* The preset and scene field tables come from the field declarations
  (``abb_gym.configuration.specs``: unit, bounds, YAML path, meaning; the columns of
  ``fields_table``), the shipped presets and scenes from their YAML files, and the validation page from the docstrings of the literature tests, which state
  each value, its tolerance and why.

Pages are written into the source folder before Sphinx reads it, and only when their text
changed (git ignores them: ``docs/.gitignore``).
"""
from __future__ import annotations

import ast
import math
import re
import textwrap
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

DOCS = Path(__file__).resolve().parents[1]
REPO = DOCS.parent
VALIDATION_TESTS = ("test_validation.py", "test_model.py", "test_analysis_lu_hung.py",
                    "test_analysis_spannan.py", "test_analysis_rotating_frame.py",
                    "test_analysis_rezaee_fathi.py", "test_analysis_timedomain.py",
                    "test_effects.py")


# --- what the environments are -------------------------------------------------------------

@dataclass(frozen=True)
class Task:
    """One environment id as the pages need it: its row of the task registry and the module
    that documents it."""

    row: object                   # abb_gym.envs.tasks.Task
    module: ModuleType            # the environment's module, whose docstring describes it

    @property
    def env_id(self) -> str:
        return self.row.env_id


def tasks() -> list[Task]:
    """Every environment id of the package, from the task registry
    (``abb_gym.envs.tasks.TASKS``, one row per id: action model, classes, default scene and
    preset, registered steps), in registration order."""
    import importlib

    from abb_gym.envs import tasks as registry
    return [Task(row, importlib.import_module(registry.load_named(row.single_class).__module__))
            for row in registry.TASKS.values()]


def env_docname(env_id: str) -> str:
    """The page of ``env_id``, relative to the docs folder, without suffix."""
    return "environments/" + env_id.replace("/", "-")


# --- Markdown-with-roles (the docstrings) to MyST ------------------------------------------

_ROLE = re.compile(r":(mod|func|class|meth|attr|data|obj|exc):`([^`]+)`")


def to_myst(text: str) -> str:
    """A docstring written in Markdown with reStructuredText roles, as MyST Markdown: roles
    become ``{py:role}`` and a pipe-table cell continued on the next line is joined to it."""
    text = _ROLE.sub(lambda m: "{py:%s}`%s`" % (m.group(1), re.sub(r"\s+", "", m.group(2))),
                     text)
    out: list[str] = []
    for line in text.splitlines():
        if out and out[-1].lstrip().startswith("|") and not out[-1].rstrip().endswith("|") \
                and line.strip():
            out[-1] = out[-1].rstrip() + " " + line.strip()
        else:
            out.append(line)
    return "\n".join(out)


def sections(doc: str) -> tuple[str, dict[str, str]]:
    """The lead paragraph of a Gymnasium-style docstring and its ``## `` sections by title."""
    parts = re.split(r"^## +(.+)$", textwrap.dedent(doc), flags=re.M)
    return parts[0].strip(), {title.strip(): body.strip()
                              for title, body in zip(parts[1::2], parts[2::2])}


def md_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c).replace("|", "\\|") for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _num(x: float) -> str:
    return f"{x:.4g}" if math.isfinite(x) else str(x)


# --- the environment pages -----------------------------------------------------------------

def observation_rows(env_id: str, scene: str, preset: str, **kwargs) -> list[list[str]]:
    """Index, name and bounds of every observation entry of an environment as ``gym.make``
    builds it (``kwargs``: observe_balls and preset overrides)."""
    from abb_gym.envs.setup import EnvSetup
    observe_balls = kwargs.pop("observe_balls", False)
    setup = EnvSetup(env_id, scene, preset, observe_balls, None, kwargs)
    space = setup.observation_space
    return [[str(i), f"`{name}`", f"[{_num(lo)}, {_num(hi)}]"]
            for i, (name, lo, hi) in enumerate(zip(setup.obs_names, space.low, space.high))]


def episode_rows(task: Task) -> list[list[str]]:
    """Per shipped scene: operating and critical speed, control interval, episode length and
    steps under the task's default preset, and the presets refused on it (with the reason)."""
    from abb_gym import list_scenes, load_scene
    from abb_gym.envs import episode_steps, list_presets
    from abb_gym.envs.setup import EnvSetup
    rows = []
    for name in list_scenes():
        scene = load_scene(name)
        refused = []
        for preset in list_presets():
            try:
                episode_steps(task.env_id, scene=name, preset=preset)
            except ValueError as exc:
                refused.append(f"`{preset}` ({_first_clause(str(exc))})")
        try:
            setup = EnvSetup(task.env_id, name, None, False, None, {})
        except ValueError as exc:
            rows.append([f"`{name}`", "", _num(scene.critical_speed), "", "", "",
                         f"every preset with the default `{task.row.default_preset}` "
                         f"({_first_clause(str(exc))})"])
            continue
        rows.append([f"`{name}`", _num(setup.operating_speed), _num(scene.critical_speed),
                     _num(setup.control_interval), _num(setup.episode_length),
                     str(episode_steps(task.env_id, scene=name)), "; ".join(refused) or "-"])
    return rows


def _first_clause(message: str) -> str:
    text = message.split(": ", 2)[-1]
    return text.split(";")[0].split(" (")[0][:120]


def preset_rows() -> list[list[str]]:
    """Every shipped preset: its description, control interval and randomised ranges."""
    import dataclasses

    from abb_gym.envs import list_presets, load_preset
    rows = []
    for name in list_presets():
        cfg = load_preset(name)
        ranges = [f"`{f.name}` {_range(getattr(cfg.randomize, f.name))}"
                  for f in dataclasses.fields(cfg.randomize)
                  if getattr(cfg.randomize, f.name) is not None]
        extras = [key for key, on in (("sync_vibration", cfg.sync_vibration.enabled),
                                      ("observe_time: false", not cfg.observe_time),
                                      (f"frame_stack {cfg.frame_stack}", cfg.frame_stack > 1))
                  if on]
        rows.append([f"`{name}`", cfg.description.strip().replace("\n", " "),
                     _num(cfg.control_interval), ", ".join(ranges) or "none",
                     ", ".join(extras) or "-"])
    return rows


def _range(value) -> str:
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_num(v) for v in value) + "]"
    return _num(value)


def env_page(task: Task) -> str:
    """The page of one environment id (MyST Markdown)."""
    from abb_gym.envs.base import COMMON_DOC
    from abb_gym.envs.setup import EnvSetup
    from abb_gym.envs.tasks import load_named
    row = task.row
    scene, preset = row.default_scene, row.default_preset
    lead, own = sections(task.module.__doc__)
    _, common = sections(COMMON_DOC)
    setup = EnvSetup(task.env_id, scene, preset, False, None, {})
    summary = lead.split(":", 1)[1].strip() if ":" in lead.splitlines()[0] else lead
    summary = summary[:1].upper() + summary[1:]
    limit = ("its own episode length (`gym.make` wraps a `TimeLimit` of exactly that many "
             "steps)" if row.registered_steps is None else
             f"{row.registered_steps} (a backstop; episodes are one step)")
    single, vector = load_named(row.single_class), load_named(row.vector_class)
    facts = md_table(["", ""], [
        ["Action space", f"`{setup.action_space}`"],
        ["Observation space", f"`Box({setup.obs_dim},)` float32 on `{scene}` / `{preset}` "
                              "(the entries below)"],
        ["Make", f'`gym.make("{task.env_id}")`: scene `{scene}`, preset `{preset}`'],
        ["Vector environment", f'`gym.make_vec("{task.env_id}", num_envs=N, '
                               f'vectorization_mode="vector_entry_point")`'],
        ["Action model", f"`{row.action}`"],
        ["Held-out preset", f"`{row.test_preset}`"],
        ["max_episode_steps", limit],
    ])
    obs = md_table(["index", "name", "bounds"], observation_rows(task.env_id, scene, preset))
    names = set(setup.obs_names)
    extra = md_table(["index", "name", "bounds"], [
        r for r in observation_rows(task.env_id, scene, preset, observe_balls=True,
                                    sync_vibration={"enabled": True})
        if r[1].strip("`") not in names])
    episodes = md_table(["scene", "operating speed [rad/s]", "critical speed [rad/s]",
                         "control interval [s]", "episode length [s]", "steps",
                         "presets refused"], episode_rows(task))
    own_sections = [part for title, body in own.items()
                    if title not in ("Description", "Action Space", "Episode length")
                    for part in (f"## {title}", "", to_myst(body), "")]
    parts = [
        "<!-- generated by docs/_ext/abb_gym_pages.py from the package: edit the code -->",
        f"# {task.env_id}", "", to_myst(summary), "", facts, "",
        "## Description", "", to_myst(own.get("Description", "")), "",
        "## Action Space", "", to_myst(own.get("Action Space", "")), "",
        "## Observation Space", "",
        to_myst(common["Observation Space"]), "",
        f"The entries on `{scene}` with the `{preset}` preset "
        f"(`env.unwrapped.observation_names` gives the same list):", "", obs, "",
        "With `observe_balls=True` and `sync_vibration={\"enabled\": True}` the entries "
        "below are added (the indices of this layout):", "", extra, "",
        "## Rewards", "", to_myst(common["Rewards"]), "",
        "## Starting State", "", to_myst(common["Starting State"]), "",
        "## Episode End", "", to_myst(common["Episode End"]), "",
        "### Episode length", "", to_myst(own.get("Episode length", "")), "",
        f"Under the default preset `{preset}` on each shipped scene (steps: "
        "`abb_gym.envs.episode_steps`, which is `env.spec.max_episode_steps`):", "",
        episodes, "",
        *own_sections,
        "## The shipped presets", "",
        "Every preset of `configs/envs/` (fields and ranges: [Presets](presets.md)):", "",
        md_table(["preset", "use", "control interval [s]", "randomised per episode",
                  "observation"], preset_rows()), "",
        "## Info", "", to_myst(common["Info"]), "",
        "## Arguments", "", to_myst(common["Arguments"]), "",
        "## Bad input", "", to_myst(common["Bad input"]), "",
        "## API", "",
        f"{{py:class}}`{single.__module__}.{single.__qualname__}`, vector "
        f"{{py:class}}`{vector.__module__}.{vector.__qualname__}`; the task's row: "
        f"{{py:mod}}`abb_gym.envs.tasks`.",
        "",
    ]
    return "\n".join(parts)


def environments_table() -> str:
    """The table of every id for the environments index (and the README's table)."""
    found = [(task, *sections(task.module.__doc__)) for task in tasks()]
    # the action's table of the first task that has one, for tasks that share its action model
    by_action: dict[str, str] = {}
    for task, _, own in found:
        by_action.setdefault(task.row.action, _action_summary(own.get("Action Space", "")))
    rows = []
    for task, lead, own in found:
        summary = lead.split(":", 1)[1].strip().rstrip(".") if ":" in lead else lead
        summary = summary[:1].upper() + summary[1:]
        action = _action_summary(own.get("Action Space", "")) or by_action[task.row.action]
        rows.append([f"[`{task.env_id}`](/{env_docname(task.env_id)}.md)",
                     to_myst(summary), action])
    return md_table(["id", "task", "action (Box [-1, 1])"], rows)


def _action_summary(text: str) -> str:
    rows = [line for line in text.splitlines() if re.match(r"\|\s*\d+\s*\|", line)]
    return "; ".join(line.split("|")[2].strip() for line in rows)


# --- presets, scenes, validation -----------------------------------------------------------

def presets_page() -> str:
    from abb_gym.envs import config
    return "\n".join([
        "<!-- generated by docs/_ext/abb_gym_pages.py from the package: edit the code -->",
        "# Presets", "",
        "A preset (`configs/envs/<name>.yaml`) fixes everything about an environment except "
        "the machine (the scene) and the action type.  Pass its name as `preset=`, or any "
        "field as a keyword to `gym.make` (`control_interval=0.05`, "
        "`reward={\"residual\": 6}`); the nested sections `reward`, `dwell`, `randomize` and "
        "`sync_vibration` merge key by key.  Errors name the field and its allowed range.", "",
        "## Shipped presets", "",
        md_table(["preset", "use", "control interval [s]", "randomised per episode",
                  "observation"], preset_rows()), "",
        "## Fields", "",
        "Declared once on `abb_gym.envs.config.EnvConfig` and its sections (unit, bounds, "
        "meaning); `null` where a scene-derived default exists.", "",
        fields_md(config._doc_rows()), "",
        "## Notes", "",
        to_myst(_after(config.__doc__, "A ``randomize`` entry")), "",
    ])


def _after(doc: str, marker: str) -> str:
    return doc[doc.index(marker):].replace("``", "`")


def scenes_page() -> str:
    from abb_gym import list_scenes, load_scene
    from abb_gym.configuration import specs
    from abb_gym.physics.scene import Scene
    rows = []
    for name in list_scenes():
        s = load_scene(name)
        rows.append([f"`{name}`", s.description, s.source, str(s.ball_count),
                     _num(s.critical_speed), _num(s.drive_operating_speed),
                     ", ".join(sorted(s.effects)) or "-"])
    return "\n".join([
        "<!-- generated by docs/_ext/abb_gym_pages.py from the package: edit the code -->",
        "# Scene reference", "",
        "A scene is one machine: a YAML file in SI units and radians, grouped into sections. "
        "Load one by name (`abb_gym.load_scene(\"yoshida_odd\")`) or by path; override any "
        "field by keyword (`load_scene(\"yoshida_odd\", ball_mass=2e-3)`) or on the command "
        "line (`--set ball_mass=2e-3`).  The keyword and `--set` name is the YAML path with "
        "its dot replaced by an underscore (`balls.mass` is `ball_mass`; the table lists "
        "both where they differ).  How to write your own: "
        "[Your own machine](engineers.md#your-own-machine).", "",
        "## Shipped scenes", "",
        md_table(["scene", "machine", "source", "balls", "critical speed [rad/s]",
                  "operating speed [rad/s]", "effects on"], rows), "",
        "## Fields", "",
        "Declared once on `abb_gym.physics.scene.Scene`: unit, allowed range, meaning.  "
        "Per-ball fields take one number or one per ball.", "",
        fields_md({n: sp for n, sp in specs(Scene).items() if n != "name"}, keywords=True), "",
        "## Rules across fields", "",
        to_myst(_paragraph(load_scene.__module__, "Cross-field rules")), "",
    ])


def fields_md(table, keywords: bool = False) -> str:
    """A Markdown table of declared fields (name -> ``abb_gym.configuration.Spec``): the
    columns of :func:`abb_gym.configuration.fields_table` (name or YAML path, unit, allowed
    range, meaning), with the keyword name beside the YAML path where they differ if
    ``keywords``."""
    from abb_gym.configuration import bounds_text
    rows = []
    for name, spec in table.items():
        unit = spec.unit or "-"
        rng = bounds_text(spec).replace(f" [{unit}]", "")
        meaning = spec.doc + (" (one per ball)" if spec.per_ball else "")
        row = [f"`{spec.yaml or name}`", unit, rng, meaning]
        if keywords:
            row.insert(1, f"`{name}`" if spec.yaml and spec.yaml != name else "")
        rows.append(row)
    header = ["YAML path", "unit", "range", "meaning"] if not keywords else \
        ["YAML path", "keyword / --set", "unit", "range", "meaning"]
    return md_table(header if keywords else ["field", *header[1:]], rows)


def _paragraph(module_name: str, start: str) -> str:
    import importlib
    doc = importlib.import_module(module_name).__doc__
    para = doc[doc.index(start):].split("\n\n")[0]
    return para.replace("``", "`")


def validation_page() -> str:
    """Every literature and model check: its test, its statement (value, tolerance, why)."""
    parts = ["<!-- generated by docs/_ext/abb_gym_pages.py from tests/: edit the tests -->",
             "# The checks, test by test", "",
             "Each check below is a test that `make test` runs; the text is the test's own "
             "docstring, which states the reference value, the tolerance and why.  Parametrised "
             "tests run once per parameter set.", ""]
    for filename in VALIDATION_TESTS:
        path = REPO / "tests" / filename
        tree = ast.parse(path.read_text())
        module_doc = ast.get_docstring(tree) or ""
        parts += [f"## `tests/{filename}`", "", _plain(module_doc.split("\n\n")[0]), ""]
        for node in tree.body:
            if isinstance(node, ast.FunctionDef) and node.name.startswith("test_"):
                doc = ast.get_docstring(node)
                if doc:
                    parts += [f"**`{node.name}`**", "", _plain(doc), ""]
    return "\n".join(parts)


def _plain(doc: str) -> str:
    """A test docstring (reStructuredText) as MyST: literals and roles."""
    doc = _ROLE.sub(lambda m: "`%s`" % m.group(2).lstrip("~"), doc)
    return re.sub(r"``(.+?)``", r"`\1`", doc, flags=re.S)


# --- the API reference ---------------------------------------------------------------------

def modules(package: str = "abb_gym") -> dict[str, list[str]]:
    """Every public module of ``package`` -> its public submodules (files and folders whose
    name does not start with ``_``), found on disk without importing them."""
    import importlib.util
    root = Path(importlib.util.find_spec(package).origin).parent
    tree: dict[str, list[str]] = {}

    def walk(folder: Path, name: str) -> None:
        children = []
        for entry in sorted(folder.iterdir()):
            if entry.name.startswith("_"):
                continue
            if entry.is_dir() and (entry / "__init__.py").is_file():
                children.append(f"{name}.{entry.name}")
                walk(entry, f"{name}.{entry.name}")
            elif entry.suffix == ".py":
                children.append(f"{name}.{entry.stem}")
                tree[f"{name}.{entry.stem}"] = []
        tree[name] = children

    walk(root, package)
    return tree


def api_pages() -> dict[str, str]:
    """One reStructuredText page per module: ``automodule`` with its members (a package's
    own, not the names it re-exports, which are documented where they are defined), and a
    table of contents of its submodules.  ``automodule`` imports each module by its name, so
    a module named like a function its package re-exports (``abb_gym.physics.simulate``) is
    documented as the module."""
    out = {}
    for name, children in modules().items():
        lines = [name, "=" * len(name), "", f".. automodule:: {name}", "   :members:",
                 "   :show-inheritance:"]
        if children:
            lines += ["   :ignore-module-all:", "", ".. toctree::", "   :maxdepth: 1", ""]
            lines += [f"   {child}" for child in children]
        out[f"api/{name}.rst"] = "\n".join(lines) + "\n"
    return out


# --- Sphinx ---------------------------------------------------------------------------------

def pages() -> dict[str, str]:
    """Every generated page: path relative to the docs folder -> text."""
    out = {env_docname(t.env_id) + ".md": env_page(t) for t in tasks()}
    out["environments/_table.md"] = environments_table() + "\n"
    out["environments/presets.md"] = presets_page()
    out["scenes.md"] = scenes_page()
    out["validation.md"] = validation_page()
    out.update(api_pages())
    return out


def write_pages(app=None) -> list[Path]:
    written = []
    for rel, text in pages().items():
        path = DOCS / rel
        if not path.exists() or path.read_text() != text:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
            written.append(path)
    return written


def setup(app):
    app.connect("builder-inited", write_pages)
    return {"parallel_read_safe": True, "parallel_write_safe": True}

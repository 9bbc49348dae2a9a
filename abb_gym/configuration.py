"""One configuration mechanism: fields declared once, one validator, one YAML reader, one
KEY=VALUE parser.

Every configuration type of abb-gym (scenes, environment presets, PPO configs, the
spring-and-rod balancer, the tuned baselines) is a dataclass whose fields are declared with
:func:`declare`: the default, the unit, the bounds, the YAML path and a line of
documentation live in one place.  From that one declaration come

* the validation (:func:`check`): a value is a result or a ``ValueError`` subclass that names
  the field, the allowed range and the unit, e.g. ``field 'rotor_mass' must be > 0 [kg]
  (got -1)``;
* the defaults (the dataclass's own);
* the documentation tables in the module docstrings (:func:`fields_table`).

Numbers are strict: ``True``/``False`` are not numbers, text is read as a number only when
it is one (YAML reads ``1e-3`` without a dot as text), and NaN and infinities are refused
unless a field allows them.

Why dataclass metadata and not pydantic or attrs + cattrs: the rules here are few (a number
in a range, an integer, a choice, a [lo, hi] range, per-ball lists), but every message must
name the field, the range and the unit in the project's words, YAML sections map to flat
fields, and ``import abb_gym`` must stay light; a 150-line module does that, where pydantic
would need a custom validator per rule and a reformatting of every message it produces.

Files: :func:`read_yaml` reads one YAML mapping and turns every way a file can be wrong
(missing, a directory, not text, not YAML, not a mapping, a key given twice, nesting deeper
than :data:`MAX_YAML_DEPTH`) into one error line naming the file; :func:`locate` resolves "a name or a path" on the search path of
:mod:`abb_gym.resources`; :func:`parse_assignments` reads ``KEY=VALUE`` options (values are
YAML, read safely: no code is evaluated).
"""
from __future__ import annotations

import copy
import dataclasses
import hashlib
import math
import os
import stat
from dataclasses import MISSING, dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

__all__ = ["ConfigError", "Spec", "declare", "specs", "check", "bounds_text", "fields_table",
           "read_yaml", "locate", "parse_assignments", "parse_yaml_value", "build",
           "parse_python_literal", "strict_yaml_load", "strict_yaml_loader", "YamlInputError",
           "MAX_YAML_DEPTH"]


MAX_FILE_BYTES = 4 * 1024 * 1024  # a configuration file is a few kB; more is a wrong file
#: the deepest nesting of mappings and lists a YAML file may have: the deepest configuration
#: (a PPO config's ``_abb_gym.eval_env_kwargs.reward``) has 4 levels; PyYAML builds nested
#: nodes recursively and a file of a few thousand levels ends in a RecursionError
MAX_YAML_DEPTH = 64


class ConfigError(ValueError):
    """A configuration value or file is invalid (the message names the field or file)."""


@dataclass(frozen=True)
class Spec:
    """How one field is checked and documented (see :func:`declare`)."""

    unit: str = "-"
    kind: str = "number"  # number, integer, flag, text, choice, range, any
    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    choices: tuple = ()
    nullable: bool = False
    doc: str = ""
    yaml: str | None = None  # path in the YAML file ("rotor.mass"); None: the field name
    per_ball: bool = False
    search: tuple | None = None  # tuners: (low, high, scale name) of the search box


def declare(default: Any = MISSING, *, factory: Callable[[], Any] | None = None,
            **spec: Any) -> Any:
    """A dataclass field with its :class:`Spec` (keywords of Spec) as metadata."""
    meta = {"spec": Spec(**spec)}
    if factory is not None:
        return dataclasses.field(default_factory=factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def specs(cls: Any) -> dict[str, Spec]:
    """Field name -> Spec of a dataclass (fields declared without one are left out)."""
    return {f.name: f.metadata["spec"] for f in dataclasses.fields(cls) if "spec" in f.metadata}


def bounds_text(spec: Spec) -> str:
    """The allowed range in words, e.g. ``> 0 [kg]``, ``in [0, 1]``, ``one of ['a', 'b']``."""
    if spec.kind == "choice":
        return f"one of {list(spec.choices)}"
    if spec.kind == "flag":
        return "true or false"
    if spec.kind == "text":
        return "text"
    lo = (f"{spec.ge:g}", "[") if spec.ge is not None else (
        (f"{spec.gt:g}", "(") if spec.gt is not None else None)
    hi = (f"{spec.le:g}", "]") if spec.le is not None else (
        (f"{spec.lt:g}", ")") if spec.lt is not None else None)
    if lo and hi:
        parts = [f"in {lo[1]}{lo[0]}, {hi[0]}{hi[1]}"]
    else:
        parts = []
        if lo:
            parts.append(f"{'>=' if lo[1] == '[' else '>'} {lo[0]}")
        if hi:
            parts.append(f"{'<=' if hi[1] == ']' else '<'} {hi[0]}")
    text = " and ".join(parts) if parts else "finite"
    if spec.kind == "integer":
        text = f"an integer {text}" if parts else "an integer"
    elif spec.kind == "range":
        text = f"[lo, hi] or one number, each {text}"
    return text + ("" if spec.unit in ("", "-") else f" [{spec.unit}]")


def is_bool(value: Any) -> bool:
    """True for Python and numpy booleans, which are never numbers here (``true`` in a YAML
    file or ``np.True_`` would otherwise pass as 1.0)."""
    kind = type(value)
    return isinstance(value, bool) or (kind.__module__ == "numpy"
                                       and kind.__name__ in ("bool", "bool_"))


def _number(spec: Spec, value: Any) -> float | None:
    """``value`` as a float within ``spec``'s bounds, or None if it is not one."""
    if is_bool(value) or value is None or isinstance(value, (bytes, bytearray)):
        return None
    if isinstance(value, str):
        try:
            value = float(value.strip())
        except ValueError:
            return None
    if getattr(value, "ndim", 0) != 0:  # float() of a one-element array is deprecated
        return None
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        return None
    if not math.isfinite(v):
        return None
    if (spec.ge is not None and v < spec.ge) or (spec.gt is not None and v <= spec.gt) \
            or (spec.le is not None and v > spec.le) or (spec.lt is not None and v >= spec.lt):
        return None
    return v


def check(where: str, name: str, value: Any, spec: Spec,
          error: type[ValueError] = ConfigError) -> Any:
    """``value`` validated and converted by ``spec``; otherwise ``error`` naming the field.

    ``where`` prefixes the message (e.g. ``scene 'yoshida_odd'``)."""
    prefix = f"{where}: " if where else ""

    def fail(what: str | None = None) -> None:
        raise error(f"{prefix}field {name!r} must be {what or bounds_text(spec)} "
                    f"(got {_short(repr(value))})")

    if value is None:
        if spec.nullable:
            return None
        fail()
    kind = spec.kind
    if kind == "any":
        return value
    if kind == "flag":
        if not isinstance(value, bool):
            fail()
        return value
    if kind == "text":
        if not isinstance(value, str):
            fail()
        return value
    if kind == "choice":
        # compared one by one: ``value in choices`` is ambiguous for an array and true for
        # True against a choice 1
        if not any((isinstance(value, str) and isinstance(c, str) or type(value) is type(c))
                   and value == c for c in spec.choices):
            fail()
        return value
    if kind == "range":
        if isinstance(value, (list, tuple)):
            if len(value) != 2:
                fail()
            lo, hi = (_number(spec, v) for v in value)
            if lo is None or hi is None:
                fail()
            if lo > hi:
                fail("[lo, hi] with lo <= hi")
            return (lo, hi)
        v = _number(spec, value)
        if v is None:
            fail()
        return (v, v)
    v = _number(spec, value)
    if v is None:
        fail()
    if kind == "integer":
        if v != int(v):
            fail()
        return int(v)
    return v


def fields_table(cls: Any, names: Iterable[str] | None = None, title: str = "field",
                 flat_names: bool = False) -> str:
    """A reStructuredText table of the declared fields of dataclass ``cls`` (or of a mapping
    name -> Spec): name, unit, allowed range, meaning; ``flat_names`` adds the field's flat
    name beside its YAML path."""
    rows = []
    table = dict(cls) if isinstance(cls, Mapping) else specs(cls)
    for name in (names or table):
        s = table[name]
        rng = bounds_text(s).replace(f" [{s.unit}]", "") if s.unit not in ("", "-") \
            else bounds_text(s)
        rows.append((s.yaml or name, *((name,) if flat_names else ()), s.unit or "-", rng,
                     s.doc))
    heads = (title, *(("flat name",) if flat_names else ()), "unit", "range", "meaning")
    widths = [max(len(h), *(len(r[k]) for r in rows)) for k, h in enumerate(heads)]
    rule = "  ".join("=" * w for w in widths)
    head = "  ".join(h.ljust(w) for h, w in zip(heads, widths))
    body = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    return "\n".join([rule, head.rstrip(), rule, *body, rule])


def build(cls: Any, values: Mapping[str, Any], where: str,
          error: type[ValueError] = ConfigError) -> Any:
    """An instance of dataclass ``cls`` from ``values``: unknown keys are refused, declared
    fields validated (fields without a Spec are passed through)."""
    table = specs(cls)
    valid = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - valid, key=str)  # a YAML key may be a number or null
    if unknown:
        raise error(f"{where}: unknown field(s) {unknown}; allowed: {sorted(valid)}")
    kwargs = {k: (check(where, k, v, table[k], error) if k in table else v)
              for k, v in values.items()}
    return cls(**kwargs)


def build_section(cls: Any, value: Any, key: str, where: str, error: type[ValueError],
                  shape: str, required: Mapping[str, str] = {}) -> Any:
    """:func:`build` for the optional mapping field ``key`` of a config (None: None).
    ``shape`` describes the mapping in the error for any other type; each ``required`` name
    must be present, its text saying what it is."""
    if value is None:
        return None
    if not isinstance(value, Mapping):
        raise error(f"{where}: field '{key}' must be {shape} or null (got {value!r})")
    for name, what in required.items():
        if name not in value:
            raise error(f"{where}: field '{key}.{name}' is missing ({what})")
    return build(cls, dict(value), f"{where} {key}", error)


# --------------------------------------------------------------------------- files
def read_yaml(path: str | os.PathLike, what: str, error: type[ValueError] = ConfigError,
              mapping: bool = True) -> Any:
    """The content of YAML file ``path`` (a mapping unless ``mapping=False``); every way the
    file can be wrong is one ``error`` naming ``what`` and the file.  Text parsed before is
    not parsed again (the file is still read and checked every time)."""
    import yaml

    p = Path(path)
    label = f"{what} file {_short(str(p))!r}"
    try:
        info = p.stat()
    except FileNotFoundError:
        raise error(f"{label} does not exist") from None
    except (OSError, ValueError) as exc:  # too long, a NUL in the name, no permission
        raise error(f"{label} cannot be opened: {getattr(exc, 'strerror', None) or exc}") \
            from None
    if stat.S_ISDIR(info.st_mode):
        raise error(f"{label} is a directory, not a YAML file")
    if not stat.S_ISREG(info.st_mode):
        # a device or a pipe (/dev/zero, /dev/stdin) would block or never end
        raise error(f"{label} is not a regular file (a device or a pipe?)")
    if info.st_size > MAX_FILE_BYTES:
        raise error(f"{label} is {info.st_size} bytes; configuration files are at most "
                    f"{MAX_FILE_BYTES} bytes")
    try:
        with open(p, "rb") as fh:
            data_bytes = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise error(f"{label} cannot be read: {exc.strerror or exc}") from None
    if len(data_bytes) > MAX_FILE_BYTES:  # grew since stat() (or /proc-like size 0)
        raise error(f"{label} is larger than {MAX_FILE_BYTES} bytes; configuration files "
                    f"are smaller")
    try:
        text = data_bytes.decode("utf-8")
    except UnicodeDecodeError:
        raise error(f"{label} is not UTF-8 text (a binary file?)") from None
    if "\x00" in text:
        raise error(f"{label} is not UTF-8 text (a binary file?)")
    key = hashlib.sha256(data_bytes).digest()
    if key not in _PARSED:
        try:
            _PARSED[key] = strict_yaml_load(text)
        except YamlInputError as exc:
            raise error(f"{label} {exc}") from None
        except yaml.YAMLError as exc:
            raise error(f"{label} is not valid YAML: {' '.join(str(exc).split())}") from None
        while len(_PARSED) > _PARSED_MAX:
            del _PARSED[next(iter(_PARSED))]
    data = copy.deepcopy(_PARSED[key])  # callers may change what they get
    if mapping:
        if data is None:
            data = {}
        if not isinstance(data, Mapping):
            raise error(f"{label} must hold a mapping of fields (got {type(data).__name__})")
    return data


class YamlInputError(ValueError):
    """YAML that parses but cannot be taken as meant: a key given twice, or nesting deeper
    than :data:`MAX_YAML_DEPTH` (the message says where, without the file's name)."""


def strict_yaml_loader() -> type:
    """PyYAML's safe loader, refusing duplicate keys and deep nesting (built on first use:
    ``import abb_gym`` does not import yaml)."""
    global _STRICT_LOADER
    if _STRICT_LOADER is not None:
        return _STRICT_LOADER
    import yaml

    class StrictSafeLoader(yaml.SafeLoader):
        """Why: PyYAML keeps the last of two equal keys without a word (a scene with
        ``drag`` twice silently used the second), and composes nested nodes recursively,
        so a deep file raised RecursionError with a traceback of thousands of lines."""

        def compose_node(self, parent, index):
            depth = getattr(self, "_depth", 0)
            if depth >= MAX_YAML_DEPTH:
                mark = self.peek_event().start_mark
                raise YamlInputError(f"line {mark.line + 1}: nesting deeper than "
                                     f"{MAX_YAML_DEPTH} levels (configuration files nest a "
                                     f"few levels)")
            self._depth = depth + 1
            try:
                return super().compose_node(parent, index)
            finally:
                self._depth = depth

        def construct_mapping(self, node, deep=False):
            if isinstance(node, yaml.MappingNode):
                seen: dict[Any, int] = {}
                for key_node, _ in node.value:
                    if key_node.tag == "tag:yaml.org,2002:merge":
                        continue  # a merged key (<<) may be overridden: that is its purpose
                    key = self.construct_object(key_node, deep=True)
                    line = key_node.start_mark.line + 1
                    try:
                        first = seen.get(key)
                        seen.setdefault(key, line)
                    except TypeError:  # an unhashable key: the base class says so
                        continue
                    if first is not None:
                        raise YamlInputError(f"line {line}: key {key!r} is given twice (also "
                                             f"on line {first}); YAML would keep only the "
                                             f"last value")
            return super().construct_mapping(node, deep=deep)

    _STRICT_LOADER = StrictSafeLoader
    return StrictSafeLoader


_STRICT_LOADER: type | None = None


def strict_yaml_load(text: str) -> Any:
    """``yaml.safe_load(text)``, but a key given twice in one mapping and nesting deeper than
    :data:`MAX_YAML_DEPTH` raise :class:`YamlInputError` naming the line."""
    import yaml
    return yaml.load(text, Loader=strict_yaml_loader())  # noqa: S506 - a SafeLoader subclass


# parsed YAML by the SHA-256 of the file's bytes: an evaluation builds an environment per
# chunk and read the same scene and preset files 34 times (a quarter of a second of parsing)
_PARSED: dict[bytes, Any] = {}
_PARSED_MAX = 256


def _short(text: str, limit: int = 200) -> str:
    """``text`` cut to ``limit`` characters for a message (a fuzzed 5000-character name must
    not flood the terminal)."""
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def _is_file(path: Path) -> bool:
    """``path.is_file()`` that is False, not an OSError, for names the system refuses (too
    long, NUL bytes, unencodable characters)."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


def locate(kind: str, name_or_path: str | os.PathLike, what: str,
           error: type[ValueError] = ConfigError) -> Path:
    """The file a name (on the search path of ``kind``, :mod:`abb_gym.resources`) or a path
    refers to; unknown names raise ``error`` listing the available ones.  Every failure,
    including an empty name (which must not read ``.``), a directory and a name the system
    refuses, is ``error`` naming the path; the file itself is checked by :func:`read_yaml`."""
    from . import resources

    text = os.fspath(name_or_path) if isinstance(name_or_path, os.PathLike) else name_or_path
    if not isinstance(text, str) or not text.strip():
        raise error(f"{what} must be a name or a path (got {_short(repr(name_or_path))}); "
                    f"available: {', '.join(resources.names(kind))}")
    path = Path(text)
    looks_like_path = text.endswith((".yaml", ".yml")) or os.sep in text or "/" in text
    if looks_like_path or _is_file(path):
        try:
            exists = path.exists()
        except (OSError, ValueError) as exc:
            raise error(f"{what} file {_short(text)!r} cannot be opened: "
                        f"{getattr(exc, 'strerror', None) or exc}") from None
        if not exists:
            raise error(f"{what} file {_short(text)!r} does not exist")
        return path
    try:
        found = resources.find(kind, text)
    except (OSError, ValueError):
        found = None
    if found is None:
        raise error(f"unknown {what} {_short(text)!r}; available: "
                    f"{', '.join(resources.names(kind)) or 'none'} (or give a path to a "
                    f"YAML file)")
    return found


def parse_yaml_value(text: str, where: str, error: type[ValueError] = ConfigError) -> Any:
    """A value written as YAML on the command line (``1e-3``, ``[1, 2]``, ``{a: 1}``)."""
    import yaml

    try:
        value = strict_yaml_load(text)
    except YamlInputError as exc:
        raise error(f"{where}: {exc}") from None
    except yaml.YAMLError as exc:
        raise error(f"{where}: {text!r} is not a valid YAML value "
                    f"({' '.join(str(exc).split()[:8])})") from None
    if isinstance(value, str):
        try:
            return float(value)  # YAML reads 1e-3 (no dot) as text
        except ValueError:
            return value
    return value


def parse_assignments(items: Iterable[str] | None, option: str,
                      error: type[ValueError] = ConfigError) -> dict[str, Any]:
    """``["a=1", "b=[1, 2]"]`` -> ``{"a": 1, "b": [1, 2]}`` (values are YAML)."""
    out: dict[str, Any] = {}
    for item in items or ():
        key, sep, value = str(item).partition("=")
        if not sep or not key.strip():
            raise error(f"{option} takes KEY=VALUE (got {item!r})")
        out[key.strip()] = parse_yaml_value(value, f"{option} {key.strip()}", error)
    return out


def parse_python_literal(text: str, names: Mapping[str, Any], where: str,
                         error: type[ValueError] = ConfigError) -> Any:
    """A zoo-style Python expression such as ``"dict(net_arch=[64, 64],
    activation_fn=nn.Tanh)"``, read without evaluating code: literals, lists, tuples, dicts,
    ``dict(key=value, ...)`` and dotted names looked up in ``names`` (``{"nn": torch.nn}``)."""
    import ast

    def value(node: ast.AST) -> Any:
        if isinstance(node, ast.Constant):
            return node.value
        if isinstance(node, (ast.List, ast.Tuple)):
            items = [value(e) for e in node.elts]
            return items if isinstance(node, ast.List) else tuple(items)
        if isinstance(node, ast.Dict):
            return {value(k): value(v) for k, v in zip(node.keys, node.values)}
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return -value(node.operand)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id == "dict" and not node.args:
            return {kw.arg: value(kw.value) for kw in node.keywords}
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                and node.value.id in names and hasattr(names[node.value.id], node.attr):
            return getattr(names[node.value.id], node.attr)
        raise error(f"{where}: {ast.unparse(node)!r} is not allowed in {text!r} (use literals, "
                    f"dict(...) and {sorted(names)} attributes)")

    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError:
        raise error(f"{where}: {text!r} is not a Python literal expression") from None
    return value(tree.body)

# SPDX-License-Identifier: GPL-3.0-or-later
"""Reading scene files: YAML as users expect it, validation, error messages naming fields."""

from __future__ import annotations

import re
import types
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ValidationError
from pydantic.fields import FieldInfo

from ..errors import SceneError
from ._fields import MAX_SCENE_BYTES
from .model import Scene


# --------------------------------------------------------------------------------------------
# YAML loading

_FLOAT_12 = re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$")


class _SceneLoader(yaml.SafeLoader):
    """SafeLoader that reads ``1e-3`` as a float (YAML 1.2, as users expect) and refuses
    duplicate keys."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, yaml.Node] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping",
                    node.start_mark,
                    f"found duplicate key {key!r}",
                    key_node.start_mark,
                )
            seen[key] = key_node
        return super().construct_mapping(node, deep=deep)


_SceneLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", _FLOAT_12, list("-+0123456789")
)


def _fmt_loc(loc: Iterable[int | str]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + part
    return out or "(top level)"


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _model_in(annotation: Any) -> type[BaseModel] | None:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        for arg in typing.get_args(annotation):
            found = _model_in(arg)
            if found is not None:
                return found
    return None


def _field_info(loc: Iterable[int | str]) -> tuple[type[BaseModel], str, FieldInfo] | None:
    """The model class, field name and FieldInfo that a validation error location points at."""
    model: type[BaseModel] | None = Scene
    found: tuple[type[BaseModel], str, FieldInfo] | None = None
    for part in loc:
        if isinstance(part, int):
            continue
        if model is None or part not in model.model_fields:
            return None
        info = model.model_fields[part]
        found = (model, part, info)
        model = _model_in(info.annotation)
    return found


def _allowed(found: tuple[type[BaseModel], str, FieldInfo] | None) -> str:
    """`` (allowed: 0 < x <= 0.1 m; Fiber length)`` for the field an error points at."""
    if found is None:
        return ""
    _, _, info = found
    extra = info.json_schema_extra if isinstance(info.json_schema_extra, dict) else {}
    unit = str(extra.get("unit", "-"))
    rng = extra.get("range")
    meaning = str(extra.get("meaning", info.description or ""))
    bits = []
    if rng and rng != "any":
        bits.append(f"allowed: {rng}" + (f" {unit}" if unit not in ("-", "1") else ""))
    elif unit not in ("-", "1"):
        bits.append(f"unit: {unit}")
    if meaning:
        bits.append(meaning)
    return f" ({'; '.join(bits)})" if bits else ""


def _with_line(path: str, key_lines: Mapping[str, int]) -> str:
    probe = path
    while probe:
        if probe in key_lines:
            return f"{path} (line {key_lines[probe]})"
        probe = re.sub(r"(\[\d+\]|\.?[^.\[]+)$", "", probe)
    return path


def _format_errors(exc: ValidationError, key_lines: Mapping[str, int]) -> list[str]:
    problems: list[str] = []
    for err in exc.errors(include_url=False):
        loc: list[int | str] = list(err["loc"])
        kind = err["type"]
        value = err.get("input")
        msg = err["msg"]
        ctx = err.get("ctx") or {}
        if kind == "field_problem":
            parts = re.split(r"[\[\].]+", ctx["field"])
            loc += [int(p) if p.isdigit() else p for p in parts if p]
            value = ctx.get("value")
            msg = ctx["message"]
        # a union of a section and None reports on the section; the None alternative is noise
        if loc and loc[-1] in ("is-instance[NoneType]",):
            continue
        # drop pydantic's names of union branches and validators ("function-after[...]")
        loc = [p for p in loc if not (isinstance(p, str) and ("[" in p or p.startswith("func")))]
        path = _with_line(_fmt_loc(loc), key_lines)
        if kind == "extra_forbidden":
            parent = _field_info(loc[:-1])
            model = _model_in(parent[2].annotation) if parent else Scene
            keys = ", ".join(model.model_fields) if model else ""
            problems.append(f"{path}: unknown key (allowed keys here: {keys})")
            continue
        found = _field_info(loc)
        if kind == "missing":
            problems.append(f"{path}: required but missing{_allowed(found)}")
            continue
        if kind == "model_type" and isinstance(value, (str, int, float, list)):
            msg = "must be a mapping (a section of key: value lines)"
        problems.append(f"{path} = {_short(value)}: {msg}{_allowed(found)}")
    # pydantic may report one problem twice through union branches
    return list(dict.fromkeys(problems))


_CANNOT = "cannot read scene"


def _key_lines(text: str) -> dict[str, int]:
    """1-based line of every key path (``fibers.length_m``, ``domain.lo_m[1]``) in the YAML."""
    lines: dict[str, int] = {}

    def walk(node: yaml.Node, path: str) -> None:
        if isinstance(node, yaml.MappingNode):
            for key, value in node.value:
                if isinstance(key, yaml.ScalarNode):
                    sub = f"{path}.{key.value}" if path else str(key.value)
                    lines.setdefault(sub, key.start_mark.line + 1)
                    walk(value, sub)
        elif isinstance(node, yaml.SequenceNode):
            for i, item in enumerate(node.value):
                sub = f"{path}[{i}]"
                lines.setdefault(sub, item.start_mark.line + 1)
                walk(item, sub)

    try:
        root = yaml.compose(text, Loader=_SceneLoader)  # noqa: S506 - SafeLoader subclass
    except yaml.YAMLError:
        return lines
    if root is not None:
        walk(root, "")
    return lines


def parse_scene(
    data: Mapping[str, Any] | Any,
    source: str = "<scene>",
    key_lines: Mapping[str, int] | None = None,
) -> Scene:
    """Validate already-loaded YAML data; raise SceneError naming every bad field.

    ``key_lines`` (field path -> line) adds line numbers to the messages."""
    if not isinstance(data, Mapping):
        raise SceneError(source, [f"(top level) = {_short(data)}: the scene must be a mapping"])
    try:
        return Scene.model_validate(data)
    except ValidationError as exc:
        raise SceneError(source, _format_errors(exc, key_lines or {})) from None


def read_scene_yaml(text: str) -> Any:
    """YAML text read as scene files are (``1e-3`` is a float, duplicate keys refused); raises
    yaml.YAMLError."""
    return yaml.load(text, Loader=_SceneLoader)  # noqa: S506 - SafeLoader subclass


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file; every failure is a SceneError (exit status 2)."""
    p = Path(path)
    source = str(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise SceneError(source, ["file not found"], _CANNOT) from None
    except IsADirectoryError:
        raise SceneError(source, ["is a directory, not a scene file"], _CANNOT) from None
    except OSError as exc:
        raise SceneError(source, [str(exc.strerror)], _CANNOT) from None
    if len(raw) > MAX_SCENE_BYTES:
        raise SceneError(
            source, [f"file too large ({len(raw)} bytes > {MAX_SCENE_BYTES})"], _CANNOT
        )
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(source, [f"not UTF-8 text (byte {exc.start})"], _CANNOT) from None
    try:
        data = read_scene_yaml(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else "unknown position"
        what = " ".join(x for x in (exc.context, exc.problem) if x)
        raise SceneError(source, [f"{where}: {what}"], "YAML syntax error") from None
    except yaml.YAMLError as exc:
        raise SceneError(source, [str(exc)], "YAML error") from None
    if data is None:
        raise SceneError(source, ["the file is empty"])
    return parse_scene(data, source, _key_lines(text))

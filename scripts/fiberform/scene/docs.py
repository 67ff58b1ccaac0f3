# SPDX-License-Identifier: GPL-3.0-or-later
"""The field table of docs/stages/scene-format.md (``fiberform schema``)."""

from __future__ import annotations

import types
import typing
from typing import Any, Literal

from pydantic import BaseModel

from .model import Scene
from .loader import _model_in


# --------------------------------------------------------------------------------------------
# Documentation


def _literal_values(annotation: Any) -> tuple[str, list[Any]] | None:
    """('one of'|'subset of', values) for Literal and list[Literal] annotations, also when
    optional (``Literal[...] | None``)."""
    origin = typing.get_origin(annotation)
    if origin is typing.Union or origin is types.UnionType:
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        return _literal_values(args[0]) if len(args) == 1 else None
    if origin is Literal:
        return "one of", list(typing.get_args(annotation))
    if origin is list:
        inner = _literal_values(typing.get_args(annotation)[0])
        if inner is not None:
            return "subset of", inner[1]
    return None


def field_table() -> str:
    """A Markdown table of every scene field: name, meaning, unit, default, range."""
    rows = ["| field | meaning | unit | default | allowed |", "|---|---|---|---|---|"]

    def walk(model: type[BaseModel], prefix: str) -> None:
        for name, info in model.model_fields.items():
            sub = _model_in(info.annotation)
            path = f"{prefix}{name}"
            if sub is not None:
                req = "required" if info.is_required() else "optional"
                rows.append(f"| **`{path}`** | {info.description} ({req} section) | | | |")
                walk(sub, path + ".")
                continue
            extra = info.json_schema_extra if isinstance(info.json_schema_extra, dict) else {}
            unit = str(extra.get("unit", "-"))
            meaning = str(extra.get("meaning", info.description or ""))
            default = (
                "required"
                if info.is_required()
                else ("absent" if info.default is None else f"`{info.default!r}`")
            )
            lit = _literal_values(info.annotation)
            allowed = (
                f"{lit[0]}: " + ", ".join(f"`{v}`" for v in lit[1])
                if lit
                else str(extra.get("range", "any"))
            )
            cells = [f"`{path}`", meaning, unit, default, allowed]
            rows.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")

    walk(Scene, "")
    return "\n".join(rows) + "\n"

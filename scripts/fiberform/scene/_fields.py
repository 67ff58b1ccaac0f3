# SPDX-License-Identifier: GPL-3.0-or-later
"""Field helpers shared by the section modules: quantities with units and ranges, choices,
identifiers, safe relative paths, the strict section base class."""

from __future__ import annotations

import re
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, ConfigDict, Field
from pydantic_core import PydanticCustomError

from ..inputs import is_identifier


MAX_SCENE_BYTES = 1 << 20

#: json_schema_extra key of fields left out of the stage hashes at their default (quantity)
HASHED_AT_DEFAULT = "hashed_at_default"
#: json_schema_extra key of fields whose listed values enter the stage hashes as other values (quantity)
HASHED_AS = "hashed_as"

# --------------------------------------------------------------------------------------------
# Field helpers


def _num(v: float) -> str:
    return str(v) if isinstance(v, int) else f"{v:g}"


def _range_text(
    gt: float | None, ge: float | None, lt: float | None, le: float | None
) -> str | None:
    lo = f"{_num(gt)} < x" if gt is not None else (f"{_num(ge)} <= x" if ge is not None else None)
    hi = f"x < {_num(lt)}" if lt is not None else (f"x <= {_num(le)}" if le is not None else None)
    if lo and hi:
        return lo + hi[1:]
    return lo or hi


def quantity(
    meaning: str,
    unit: str,
    *,
    default: Any = ...,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    hashed_at_default: bool = True,
    hashed_as: dict[float, float] | None = None,
) -> Any:
    """A numeric field: ``meaning`` and ``unit`` go into the description (``1`` = dimensionless).

    ``hashed_at_default=False``: the field is left out of the stage hashes while it holds its
    default (:func:`fiberform.scene.model.section_hash`). For fields added to a section whose
    default reproduces what the stage did before they existed: finished products stay up to date.
    ``hashed_as`` {value: recorded}: the value enters the stage hashes as ``recorded``; for a field
    whose earlier versions recorded ``recorded`` in the hashes while the stage computed with
    ``value`` (a field that reached nothing): those products stay up to date, as they should."""
    rng = _range_text(gt, ge, lt, le)
    extra: dict[str, Any] = {"unit": unit, "meaning": meaning, "range": rng or "any"}
    if not hashed_at_default:
        extra[HASHED_AT_DEFAULT] = False
    if hashed_as:
        extra[HASHED_AS] = [[float(k), float(v)] for k, v in hashed_as.items()]
    return Field(
        default,
        description=f"{meaning} [{unit}]",
        gt=gt,
        ge=ge,
        lt=lt,
        le=le,
        json_schema_extra=extra,
    )


def _element_range(
    meaning: str, unit: str, rng: str, default: Any = ..., length: int = 3
) -> Any:
    return Field(
        default,
        description=f"{meaning} [{unit}]",
        min_length=length,
        max_length=length,
        json_schema_extra={
            "unit": unit,
            "meaning": meaning,
            "range": f"{length} values, each {rng}",
        },
    )


def choice(meaning: str, *, default: Any = ...) -> Any:
    """A field whose type is a ``Literal`` (or a list of one)."""
    return Field(default, description=meaning, json_schema_extra={"unit": "-", "meaning": meaning})


def _check_identifier(value: str) -> str:
    if not is_identifier(value):
        raise PydanticCustomError(
            "identifier",
            "not an identifier (a letter followed by up to 63 letters, digits or underscores)",
        )
    return value


Identifier = Annotated[str, AfterValidator(_check_identifier)]

_PATH_PART = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}")


def _check_relative_path(value: str) -> str:
    bad = PydanticCustomError(
        "relative_path",
        "not a safe relative path (up to 16 parts separated by '/', each of letters, digits, "
        "'_', '.', '-', not starting with '.' or '-'; no '..', not absolute)",
    )
    if value.startswith("/") or "\\" in value or value.endswith("/"):
        raise bad
    parts = value.split("/")
    if not 1 <= len(parts) <= 16:
        raise bad
    for part in parts:
        if _PATH_PART.fullmatch(part) is None or part in (".", ".."):
            raise bad
    return value


RelativePath = Annotated[str, AfterValidator(_check_relative_path)]


def scene_problem(field: str, message: str, value: Any = None) -> PydanticCustomError:
    """An error for a cross-field check, attached to ``field`` of the section being validated."""
    return PydanticCustomError(
        "field_problem", "{message}", {"field": field, "value": value, "message": message}
    )


class _Section(BaseModel):
    model_config = ConfigDict(
        extra="forbid",
        strict=True,
        allow_inf_nan=False,
        frozen=True,
        validate_default=True,
    )


Coordinate = Annotated[float, Field(ge=-10.0, le=10.0)]
Acceleration = Annotated[float, Field(ge=-1000.0, le=1000.0)]

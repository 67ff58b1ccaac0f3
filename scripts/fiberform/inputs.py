# SPDX-License-Identifier: GPL-3.0-or-later
"""The only way values reach generated LIGGGHTS and OpenFOAM input text.

LIGGGHTS input scripts can run programs (``shell``), OpenFOAM dictionaries can compile and run
code (``#codeStream``, ``#calc``). A scene file is user input, so nothing from it is pasted as
text: every value goes through one of the formatters below, which accept only

* finite floats (written with :func:`repr`, the shortest text that reads back to the same double),
* ints (not bools),
* identifiers matching ``^[A-Za-z][A-Za-z0-9_]{0,63}$``,

and raise :class:`~fiberform.errors.InputFormatError` for anything else. Command and style names
(``pair_style``, ``nve/sphere``) are words written by fiberform's own code; they are checked against
a stricter pattern too, so a mistake cannot open a hole either.
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Sequence
from typing import Literal

from .errors import InputFormatError

__all__ = [
    "IDENTIFIER_PATTERN",
    "LiggghtsInput",
    "STAR",
    "Token",
    "dump_format",
    "file_token",
    "fix_affine",
    "fix_ref",
    "ident_list",
    "jump_if_at_least",
    "fmt_float",
    "fmt_ident",
    "fmt_int",
    "fmt_value",
    "foam_entry",
    "foam_value",
    "is_identifier",
]

#: Identifiers: a letter, then up to 63 letters, digits or underscores (checked with fullmatch,
#: so a trailing newline does not slip through as it would with ``re.match`` and ``$``).
IDENTIFIER_PATTERN = r"[A-Za-z][A-Za-z0-9_]{0,63}"
_IDENTIFIER = re.compile(IDENTIFIER_PATTERN)
# Words of fiberform's own code: identifiers optionally joined by '/', as style names are.
_WORD = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,63}(?:/[A-Za-z0-9_]{1,64}){0,3}")
# Commands that execute programs or other files; never written by fiberform.
_FORBIDDEN_COMMANDS = frozenset({"shell", "python", "include", "jump", "label", "next"})


def is_identifier(value: object) -> bool:
    """True if ``value`` is a str matching :data:`IDENTIFIER_PATTERN` in full."""
    return isinstance(value, str) and _IDENTIFIER.fullmatch(value) is not None


def fmt_float(value: object) -> str:
    """Format a finite real number with full precision (``repr`` of the double)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InputFormatError(f"refusing to write {value!r}: not a number")
    x = float(value)
    if not math.isfinite(x):
        raise InputFormatError(f"refusing to write {value!r}: not a finite number")
    return repr(x)


def fmt_int(value: object) -> str:
    """Format an integer (bools are refused)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise InputFormatError(f"refusing to write {value!r}: not an integer")
    return str(int(value))


def fmt_ident(value: object) -> str:
    """Return ``value`` unchanged if it is a validated identifier, else raise."""
    if not is_identifier(value):
        raise InputFormatError(
            f"refusing to write {value!r}: not an identifier ({IDENTIFIER_PATTERN})"
        )
    assert isinstance(value, str)
    return value


def fmt_value(value: object) -> str:
    """Format an int, a finite float or an identifier; raise for anything else."""
    if isinstance(value, bool):
        raise InputFormatError(f"refusing to write {value!r}: booleans have no input syntax here")
    if isinstance(value, numbers.Integral):
        return fmt_int(value)
    if isinstance(value, numbers.Real):
        return fmt_float(value)
    if isinstance(value, str):
        return fmt_ident(value)
    raise InputFormatError(f"refusing to write {value!r} of type {type(value).__name__}")


class Token:
    """A piece of input text built by this module only (not from user strings)."""

    __slots__ = ("text",)

    def __init__(self, text: str, _key: object = None) -> None:
        if _key is not _TOKEN_KEY:
            raise InputFormatError("Token objects are made by fiberform.inputs functions only")
        self.text = text

    def __repr__(self) -> str:
        return f"Token({self.text!r})"

    def __str__(self) -> str:
        return self.text


_TOKEN_KEY = object()
#: The ``*`` wildcard of ``pair_coeff * *``.
STAR = Token("*", _TOKEN_KEY)


def dump_format(columns: Sequence[Literal["int", "float"]]) -> Token:
    """The quoted ``dump_modify ... format`` string: ``%d`` for ints, ``%.17g`` for floats."""
    parts: list[str] = []
    for c in columns:
        if c == "int":
            parts.append("%d")
        elif c == "float":
            parts.append("%.17g")
        else:
            raise InputFormatError(f"unknown dump column kind {c!r}")
    if not parts:
        raise InputFormatError("empty dump format")
    return Token('"' + " ".join(parts) + '"', _TOKEN_KEY)


_FILE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}")


def file_token(name: str) -> Token:
    """A plain file name in the working folder (letters, digits, ``_ . -``; no ``/``, no
    leading ``.`` or ``-``), e.g. ``final.dump``."""
    if not isinstance(name, str) or _FILE_NAME.fullmatch(name) is None:
        raise InputFormatError(f"refusing file name {name!r}")
    return Token(name, _TOKEN_KEY)


def step_file_token(stem: str, ext: str) -> Token:
    """A LIGGGHTS file name with the step substituted for ``*`` (``stem.*.ext``, e.g. the files of
    the ``restart`` command); stem and ext are plain file names as for :func:`file_token`."""
    for part in (stem, ext):
        if not isinstance(part, str) or _FILE_NAME.fullmatch(part) is None:
            raise InputFormatError(f"refusing file name part {part!r}")
    return Token(f"{stem}.*.{ext}", _TOKEN_KEY)


def ident_list(names: Sequence[str]) -> Token:
    """A comma-separated list of identifiers as one word (e.g. the `terms vdw,es,steric` of the
    contact styles); every name must be an identifier."""
    if isinstance(names, str) or not names:
        raise InputFormatError(f"refusing identifier list {names!r}")
    return Token(",".join(fmt_ident(n) for n in names), _TOKEN_KEY)


def fix_ref(fix_id: str, index: int | None = None, negate: bool = False) -> Token:
    """A reference to a fix's global value, ``f_ID`` or ``f_ID[n]`` (thermo, variables);
    ``negate``: ``-f_ID[n]`` (an equal-style variable's formula)."""
    text = ("-" if negate else "") + "f_" + fmt_ident(fix_id)
    if index is not None:
        if isinstance(index, bool) or not isinstance(index, int) or not 1 <= index <= 99:
            raise InputFormatError(f"refusing fix vector index {index!r}")
        text += f"[{index}]"
    return Token(text, _TOKEN_KEY)


def fix_sum(refs: Sequence[tuple[str, int]]) -> Token:
    """The sum of fix vector values, ``f_A[i]+f_B[j]+...``, as an equal-style variable's formula."""
    if not refs:
        raise InputFormatError("refusing an empty sum of fix values")
    return Token("+".join(fix_ref(f, i).text for f, i in refs), _TOKEN_KEY)


def var_ref(name: str) -> Token:
    """A reference to an equal-style variable, ``v_NAME`` (thermo output)."""
    return Token("v_" + fmt_ident(name), _TOKEN_KEY)


def var_value(name: str) -> Token:
    """``${NAME}``: the variable's value substituted into the command when LIGGGHTS reads it
    (an equal-style variable is evaluated then, printed with 15 significant digits)."""
    return Token("${" + fmt_ident(name) + "}", _TOKEN_KEY)


def fix_affine(fix_id: str, index: int, scale: float, offset: float | Token) -> Token:
    """``OFFSET+SCALE*f_ID[n]``, an equal-style variable's formula (a fix value in other units or
    from another origin, e.g. a plate's height from its displacement); the offset a number or a
    token of this module (e.g. :func:`var_value`, a variable's value when the command is read)."""
    off = offset.text if isinstance(offset, Token) else fmt_float(offset)
    return Token(off + "+" + fmt_float(scale) + "*" + fix_ref(fix_id, index).text, _TOKEN_KEY)


def var_affine(name: str, scale: float, offset: float) -> Token:
    """``OFFSET+SCALE*v_NAME``, an equal-style variable's formula (another variable's value from
    another origin or in other units)."""
    return Token(fmt_float(offset) + "+" + fmt_float(scale) + "*" + var_ref(name).text, _TOKEN_KEY)


def var_distance(name: str, value: float) -> Token:
    """``abs(v_NAME-VALUE)``, an equal-style variable's formula."""
    return Token("abs(" + var_ref(name).text + "-" + fmt_float(value) + ")", _TOKEN_KEY)


def print_values(marker: str, *names: str) -> Token:
    """The quoted text of ``print``: a marker and the values of variables, ``"MARKER ${a} ${b}"``
    (a log line the stage parses)."""
    return Token('"' + " ".join([fmt_ident(marker), *(var_value(n).text for n in names)]) + '"', _TOKEN_KEY)


def jump_if_at_least(variable: str, threshold: int | float, label: str,
                     marker: str = "FIBERFORM_QUIT") -> tuple[Token, ...]:
    """Arguments of ``if "${variable} >= threshold" then "print MARKER" "jump SELF label"``: leave
    a loop of ``run`` commands for the commands after ``label LABEL`` when a variable (an
    identifier) reaches a number (settle criteria); the marker line records the early end."""
    cond = '"${' + fmt_ident(variable) + "} >= " + fmt_value(threshold) + '"'
    return (Token(cond, _TOKEN_KEY), Token("then", _TOKEN_KEY),
            Token('"print ' + fmt_ident(marker) + '"', _TOKEN_KEY),
            Token('"jump SELF ' + fmt_ident(label) + '"', _TOKEN_KEY))


def _arg(value: object) -> str:
    if isinstance(value, Token):
        return value.text
    if isinstance(value, str):
        if _WORD.fullmatch(value) is None:
            raise InputFormatError(f"refusing to write {value!r}: not an identifier or style name")
        return value
    return fmt_value(value)


class LiggghtsInput:
    """A LIGGGHTS input script assembled command by command.

    >>> s = LiggghtsInput()
    >>> s.command("timestep", 1e-6)
    >>> s.render()
    'timestep 1e-06\\n'
    """

    def __init__(self) -> None:
        self._lines: list[str] = []

    def comment(self, text: str) -> None:
        """A comment line; printable ASCII only, so it cannot end the line or continue it."""
        if re.fullmatch(r"[ -~]*", text) is None or text.rstrip().endswith("&"):
            raise InputFormatError(f"refusing comment {text!r}")
        self._lines.append(f"# {text}" if text else "#")

    def blank(self) -> None:
        self._lines.append("")

    def command(self, name: str, *args: object) -> None:
        """One command line: ``name`` is a LIGGGHTS command, ``args`` words, numbers or Tokens."""
        if not isinstance(name, str) or _WORD.fullmatch(name) is None:
            raise InputFormatError(f"refusing command name {name!r}")
        if name in _FORBIDDEN_COMMANDS:
            raise InputFormatError(f"refusing to write the command {name!r}")
        self._lines.append(" ".join([name, *(_arg(a) for a in args)]))

    def label(self, name: str) -> None:
        """``label NAME`` (an identifier): the target of :func:`jump_if_at_least`. ``command``
        refuses ``label`` and ``jump``; these two are the only ways to write them."""
        self._lines.append("label " + fmt_ident(name))

    def render(self) -> str:
        return "\n".join(self._lines) + "\n"


def foam_value(value: object) -> str:
    """An OpenFOAM dictionary value: a number, an identifier, or a list/tuple of numbers
    written as ``(a b c)``."""
    if isinstance(value, (list, tuple)):
        return "(" + " ".join(fmt_value(v) for v in value) + ")"
    if isinstance(value, str) and value.startswith("#"):
        raise InputFormatError(f"refusing to write the OpenFOAM directive {value!r}")
    return fmt_value(value)


def foam_entry(key: str, value: object) -> str:
    """``key value;`` with an identifier key."""
    return f"{fmt_ident(key)} {foam_value(value)};"

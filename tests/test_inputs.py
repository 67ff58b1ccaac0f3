# SPDX-License-Identifier: GPL-3.0-or-later
"""The formatting helpers of fiberform.inputs: only finite numbers, ints and identifiers reach
LIGGGHTS/OpenFOAM text; everything else raises."""

from __future__ import annotations

import math
from decimal import Decimal
from fractions import Fraction

import numpy as np
import pytest

from fiberform.errors import InputFormatError
from fiberform.inputs import (
    STAR,
    LiggghtsInput,
    Token,
    dump_format,
    file_token,
    fmt_float,
    fmt_ident,
    fmt_int,
    fmt_value,
    foam_entry,
    foam_value,
    is_identifier,
    fix_affine,
    print_values,
    var_distance,
    var_value,
)

INJECTIONS = [
    "x\nshell rm -rf /",
    "x; shell touch /tmp/pwned",
    "shell touch /tmp/pwned",
    "#codeStream",
    '#codeStream { code #{ system("touch /tmp/pwned"); #}; }',
    '#calc "1+1"',
    "${x}",
    "$(touch /tmp/pwned)",
    "a &",
    "a\n",
    "a\r",
    "a b",
    "a\tb",
    '"quoted"',
    "a#b",
    "",
    "1abc",
    "_abc",
    "a" * 65,
    "ä",
    "a/b",
    "a.b",
]


@pytest.mark.parametrize(
    "value", [0.0, 1.0, -2.5, 0.1, 1.0 / 3.0, 1e-300, 6.02214076e23, 5e-324, np.float64(0.1), 3]
)
def test_fmt_float_round_trips(value: float) -> None:
    text = fmt_float(value)
    assert float(text) == float(value)
    assert " " not in text and "\n" not in text


@pytest.mark.parametrize(
    "value", [math.nan, math.inf, -math.inf, True, False, "1.0", None, [1.0], Decimal("1.0"), 1j]
)
def test_fmt_float_refuses(value: object) -> None:
    with pytest.raises(InputFormatError):
        fmt_float(value)


def test_fmt_float_accepts_fraction_as_real() -> None:
    assert float(fmt_float(Fraction(1, 4))) == 0.25


@pytest.mark.parametrize(
    "value,text", [(0, "0"), (-7, "-7"), (2**40, str(2**40)), (np.int64(5), "5")]
)
def test_fmt_int(value: int, text: str) -> None:
    assert fmt_int(value) == text


@pytest.mark.parametrize("value", [True, 1.0, "1", None, np.float64(1.0)])
def test_fmt_int_refuses(value: object) -> None:
    with pytest.raises(InputFormatError):
        fmt_int(value)


@pytest.mark.parametrize("value", ["a", "abc", "A_1", "x" + "y" * 63, "demo", "fiber_dlvo"])
def test_fmt_ident_accepts(value: str) -> None:
    assert fmt_ident(value) == value
    assert is_identifier(value)


@pytest.mark.parametrize("value", INJECTIONS)
def test_fmt_ident_refuses_injections(value: str) -> None:
    assert not is_identifier(value)
    with pytest.raises(InputFormatError):
        fmt_ident(value)
    with pytest.raises(InputFormatError):
        fmt_value(value)


@pytest.mark.parametrize("value", [None, True, [1], (1, 2), {"a": 1}, b"abc", object(), math.nan])
def test_fmt_value_refuses_other_types(value: object) -> None:
    with pytest.raises(InputFormatError):
        fmt_value(value)


def test_fmt_value_dispatch() -> None:
    assert fmt_value(3) == "3"
    assert fmt_value(3.0) == "3.0"
    assert fmt_value(1e-6) == "1e-06"
    assert fmt_value("abc") == "abc"


def test_liggghts_script_renders() -> None:
    s = LiggghtsInput()
    s.comment("two spheres")
    s.command("units", "si")
    s.command("pair_style", "test/harmonic")
    s.command("pair_coeff", STAR, STAR, 1000.0)
    s.command("create_atoms", 1, "single", -1.5e-3, 0.0, 0.0, "units", "box")
    s.command("dump", "d", "all", "custom", 10, file_token("final.dump"), "id", "x")
    s.command("dump_modify", "d", "format", dump_format(["int", "float"]))
    assert s.render() == (
        "# two spheres\n"
        "units si\n"
        "pair_style test/harmonic\n"
        "pair_coeff * * 1000.0\n"
        "create_atoms 1 single -0.0015 0.0 0.0 units box\n"
        "dump d all custom 10 final.dump id x\n"
        'dump_modify d format "%d %.17g"\n'
    )


@pytest.mark.parametrize("value", INJECTIONS[:-2] + ["a//b", "/abs", "a/"])
def test_liggghts_arguments_refuse_injections(value: str) -> None:
    s = LiggghtsInput()
    with pytest.raises(InputFormatError):
        s.command("region", value)
    with pytest.raises(InputFormatError):
        s.command(value)
    assert s.render() == "\n"  # nothing was added


@pytest.mark.parametrize("name", ["shell", "python", "include", "jump", "label", "next"])
def test_liggghts_refuses_commands_that_run_things(name: str) -> None:
    with pytest.raises(InputFormatError):
        LiggghtsInput().command(name, "touch")


@pytest.mark.parametrize("text", ["a\nshell rm -rf /", "continued &", "tab\there", "é"])
def test_liggghts_comment_refuses(text: str) -> None:
    with pytest.raises(InputFormatError):
        LiggghtsInput().comment(text)


def test_tokens_cannot_be_made_from_outside() -> None:
    with pytest.raises(InputFormatError):
        Token("shell rm -rf /")


@pytest.mark.parametrize("name", ["../x", "a/b", "-x", ".x", "a b", "a\nb", "", "x;y"])
def test_file_token_refuses(name: str) -> None:
    with pytest.raises(InputFormatError):
        file_token(name)


def test_dump_format_only_known_columns() -> None:
    assert dump_format(["int", "float", "float"]).text == '"%d %.17g %.17g"'
    with pytest.raises(InputFormatError):
        dump_format(["%s"])  # type: ignore[list-item]
    with pytest.raises(InputFormatError):
        dump_format([])


def test_foam_helpers() -> None:
    assert foam_entry("nu", 1.0e-6) == "nu 1e-06;"
    assert foam_entry("nAlphaCorr", 2) == "nAlphaCorr 2;"
    assert foam_entry("solver", "PCG") == "solver PCG;"
    assert foam_value([0.0, 0.0, -9.81]) == "(0.0 0.0 -9.81)"


@pytest.mark.parametrize("value", INJECTIONS[:4] + ['#include "x"', "#calc", "#codeStream"])
def test_foam_helpers_refuse_injections(value: str) -> None:
    with pytest.raises(InputFormatError):
        foam_value(value)
    with pytest.raises(InputFormatError):
        foam_entry(value, 1.0)
    with pytest.raises(InputFormatError):
        foam_entry("key", value)
    with pytest.raises(InputFormatError):
        foam_value([1.0, value])


def test_ident_list_accepts_identifiers_only() -> None:
    from fiberform.errors import InputFormatError
    from fiberform.inputs import ident_list

    assert str(ident_list(["vdw", "es", "steric"])) == "vdw,es,steric"
    for bad in (["vdw", "es steric"], ["vdw\nshell ls"], [], "vdw", ["1abc"]):
        with pytest.raises(InputFormatError):
            ident_list(bad)  # type: ignore[arg-type]


def test_variable_formula_helpers() -> None:
    """The press's approach variables: numbers at full precision, identifiers only."""
    assert fix_affine("plate", 10, -1.0, 0.0027956425032346598).text == \
        "0.0027956425032346598+-1.0*f_plate[10]"
    assert var_value("servo_z").text == "${servo_z}"
    assert var_distance("servo_z", 0.002637).text == "abs(v_servo_z-0.002637)"
    assert print_values("FIBERFORM_SERVO_START", "servo_step", "servo_z").text == \
        '"FIBERFORM_SERVO_START ${servo_step} ${servo_z}"'


@pytest.mark.parametrize("value", INJECTIONS)
def test_variable_formula_helpers_refuse_injections(value: str) -> None:
    for make in (lambda: var_value(value), lambda: var_distance(value, 1.0),
                 lambda: print_values(value), lambda: print_values("M", value),
                 lambda: fix_affine(value, 1, 1.0, 0.0)):
        with pytest.raises(InputFormatError):
            make()
    with pytest.raises(InputFormatError):
        fix_affine("plate", 1, math.nan, 0.0)

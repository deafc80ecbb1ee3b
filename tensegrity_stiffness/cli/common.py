"""What every command group shares: the exit codes, the number parsing of the options (``pi``
arithmetic, negative numbers), the table formatting and the JSON output."""

from __future__ import annotations

import argparse
import ast
import json
import math
import operator
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness.geometry.components import TWIST_NAMES

FloatArray = NDArray[np.float64]

PROG = 'tensegrity-stiffness'
EXIT_OK = 0
EXIT_NO_SOLUTION = 1
EXIT_BAD_INPUT = 2
EXIT_NO_MATPLOTLIB = 3

#: Table cells: width (characters) and relative size below which an entry is shown as 0.
CELL_WIDTH = 13
DISPLAY_ZERO = 1e-12
#: Longest accepted numeric expression (characters).
MAX_EXPRESSION_LENGTH = 100
#: Column labels of K_c: a spatial twist in {1}, linear first (the node's labels).
KC_COLUMN_NAMES = TWIST_NAMES


# ------------------------------------------------------------------------------ input parsing
_BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
           ast.Div: operator.truediv, ast.Pow: operator.pow}
_UNARY = {ast.UAdd: operator.pos, ast.USub: operator.neg}


def _evaluate(node: ast.AST) -> float:
    """Value of a parsed arithmetic expression of numbers and ``pi`` (nothing else)."""
    if isinstance(node, ast.Expression):
        return _evaluate(node.body)
    if isinstance(node, ast.Constant) and type(node.value) in (int, float):
        return float(node.value)
    if isinstance(node, ast.Name) and node.id == 'pi':
        return math.pi
    if isinstance(node, ast.UnaryOp) and type(node.op) in _UNARY:
        return _UNARY[type(node.op)](_evaluate(node.operand))
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
        return float(_BINARY[type(node.op)](_evaluate(node.left), _evaluate(node.right)))
    raise ValueError('not an arithmetic expression')


def parse_number(text: str) -> float:
    """A finite float from ``text``: a number or arithmetic with ``pi`` (e.g. ``-3*pi/4``)."""
    s = str(text).strip()
    try:
        if len(s) > MAX_EXPRESSION_LENGTH:
            raise ValueError('too long')
        value = _evaluate(ast.parse(s, mode='eval'))
    except (SyntaxError, ValueError, TypeError, ZeroDivisionError, OverflowError,
            RecursionError):
        raise argparse.ArgumentTypeError(
            f'not a number: {s!r} (examples: 0.5, -1e-3, pi/10)') from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'not a finite number: {s!r}')
    return value


def positive_int(text: str) -> int:
    """An integer >= 1 (an option's type)."""
    try:
        value = int(str(text).strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f'not an integer: {text!r}') from None
    if value < 1:
        raise argparse.ArgumentTypeError(f'must be >= 1, got {value}')
    return value


def _is_number(token: str) -> bool:
    try:
        parse_number(token)
    except argparse.ArgumentTypeError:
        return False
    return True


def protect_negative_numbers(argv: Sequence[str]) -> list[str]:
    """argparse takes ``-1e-3`` or ``-pi/2`` for an option: prefix such numbers with a space
    (stripped again by :func:`parse_number`) so that they are read as values."""
    out = []
    for token in argv:
        if len(token) > 1 and token[0] == '-' and token[1] != '-' and _is_number(token):
            token = ' ' + token
        out.append(token)
    return out


def add_json(p: argparse.ArgumentParser) -> None:
    """The ``--json`` option."""
    p.add_argument('--json', action='store_true', help='machine-readable JSON output')


# ------------------------------------------------------------------------------ formatting
def num(value: float, width: int = 0) -> str:
    """``value`` to 6 significant digits (``nan`` for NaN, inf and None), right-aligned."""
    text = 'nan' if value is None or not math.isfinite(value) else f'{value:.6g}'
    if text == '-0':
        text = '0'
    return text.rjust(width)


def vector(values: Sequence[float] | FloatArray) -> str:
    """``[a b c]`` of :func:`num`."""
    return '[' + ' '.join(num(float(v)) for v in values) + ']'


def display(values: FloatArray) -> FloatArray:
    """``values`` with entries below :data:`DISPLAY_ZERO` times the largest shown as 0 (tables
    only; JSON carries the exact values)."""
    values = np.asarray(values, dtype=np.float64)
    finite = values[np.isfinite(values)]
    scale = float(np.abs(finite).max()) if finite.size else 0.0
    return np.where(np.abs(values) < DISPLAY_ZERO * scale, 0.0, values)


def matrix_lines(M: FloatArray, rows: Sequence[str], cols: Sequence[str],
                 width: int = CELL_WIDTH) -> list[str]:
    """A labelled table of ``M``, one line per row."""
    lines = ['      ' + ''.join(c.rjust(width) for c in cols)]
    for name, row in zip(rows, display(M), strict=True):
        lines.append(f'  {name:<4}' + ''.join(num(float(v), width) for v in row))
    return lines


def jsonable(obj: Any) -> Any:
    """numpy -> plain Python; NaN and inf -> None (strict JSON)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


def print_json(obj: Any) -> None:
    """``obj`` as indented strict JSON on stdout."""
    print(json.dumps(jsonable(obj), indent=2, allow_nan=False))


def yes(flag: bool) -> str:
    """``yes`` or ``no``."""
    return 'yes' if flag else 'no'

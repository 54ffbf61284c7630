"""Soft regions painted on a mesh: per-vertex weights in [0, 1] from an expression or a file.

Used as the grafting mask of the cellular automaton (which of two models grows where). An
expression is a formula in the vertex coordinates ``x``, ``y``, ``z`` (the mesh normalised to the unit
ball, y up), e.g. ``x > 0`` (a hard half), ``smoothstep(-0.2, 0.2, x)`` (a soft seam) or
``sigmoid((y - 0.3) / 0.05)``. Allowed: numbers, + - * / ** and comparisons, and the functions
abs, sqrt, exp, sin, cos, minimum, maximum, clip, sigmoid and smoothstep. Nothing else is evaluated:
the expression is parsed, never passed to ``eval``.
"""

from __future__ import annotations

import ast
import operator
from pathlib import Path

import numpy as np

from mesh2tex.checks import check_array_shape
from mesh2tex.errors import InputError


def _sigmoid(x):
    return 1.0 / (1.0 + np.exp(-np.asarray(x, dtype=np.float64)))


def _smoothstep(edge0, edge1, x):
    t = np.clip((np.asarray(x, dtype=np.float64) - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


FUNCTIONS = {
    "abs": np.abs,
    "sqrt": np.sqrt,
    "exp": np.exp,
    "sin": np.sin,
    "cos": np.cos,
    "minimum": np.minimum,
    "maximum": np.maximum,
    "clip": np.clip,
    "sigmoid": _sigmoid,
    "smoothstep": _smoothstep,
}
_BINARY = {
    ast.Add: operator.add,
    ast.Sub: operator.sub,
    ast.Mult: operator.mul,
    ast.Div: operator.truediv,
    ast.Pow: operator.pow,
}
_COMPARE = {ast.Gt: operator.gt, ast.GtE: operator.ge, ast.Lt: operator.lt, ast.LtE: operator.le}


def _evaluate(node, names: dict[str, np.ndarray]):
    if isinstance(node, ast.Expression):
        return _evaluate(node.body, names)
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        # numpy scalars: 10**400 or 1/0 become inf (refused as not finite below), not Python's OverflowError
        # or ZeroDivisionError; a negative base to a fractional power is NaN, not a complex number
        return np.float64(node.value) if abs(node.value) < 1e308 else np.float64(np.inf)
    if isinstance(node, ast.Name) and node.id in names:
        return names[node.id]
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        value = _evaluate(node.operand, names)
        return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
        return _BINARY[type(node.op)](_evaluate(node.left, names), _evaluate(node.right, names))
    if isinstance(node, ast.Compare) and len(node.ops) == 1 and type(node.ops[0]) in _COMPARE:
        result = _COMPARE[type(node.ops[0])](_evaluate(node.left, names), _evaluate(node.comparators[0], names))
        return np.asarray(result, dtype=np.float64)
    if (
        isinstance(node, ast.Call)
        and isinstance(node.func, ast.Name)
        and node.func.id in FUNCTIONS
        and not node.keywords
    ):
        return FUNCTIONS[node.func.id](*(_evaluate(a, names) for a in node.args))
    raise ValueError(f"'{ast.unparse(node)}' is not allowed")


MAX_EXPRESSION_CHARS = 1000  # longer is no hand-written mask; the parser's recursion and memory stay bounded


def expression_weights(expression: str, positions: np.ndarray) -> np.ndarray:
    """(V,) float32 in [0, 1]: ``expression`` evaluated at positions (V, 3), clipped. InputError (one
    line quoting at most 80 characters of it) for one that cannot be parsed or evaluated, or whose
    value overflows or is undefined at some vertex."""
    check_array_shape(positions, "expression_weights: positions", ("V", 3))
    positions = np.asarray(positions, dtype=np.float64)
    names = {"x": positions[:, 0], "y": positions[:, 1], "z": positions[:, 2]}
    shown = repr(expression if len(expression) <= 80 else expression[:77] + "...")
    if len(expression) > MAX_EXPRESSION_CHARS:
        raise InputError(
            f"graft mask {shown}: {len(expression)} characters; an expression holds at most {MAX_EXPRESSION_CHARS} "
            f"(a per-vertex .npy or .txt file takes any mask)"
        )
    try:
        tree = ast.parse(expression, mode="eval")
        with np.errstate(all="ignore"):
            value = np.broadcast_to(np.asarray(_evaluate(tree, names), dtype=np.float64), (positions.shape[0],))
    except (SyntaxError, ValueError, TypeError, ArithmeticError) as error:
        raise InputError(
            f"graft mask {shown}: {error} (use x, y, z, numbers, + - * / **, comparisons and "
            f"{', '.join(sorted(FUNCTIONS))})"
        ) from None
    except (RecursionError, MemoryError):  # nested too deep for the parser
        raise InputError(f"graft mask {shown}: nested too deeply") from None
    if not np.all(np.isfinite(value)):
        raise InputError(
            f"graft mask {shown}: not finite at some vertices (an overflow, a division by zero or a root of a "
            "negative number)"
        )
    return np.clip(value, 0.0, 1.0).astype(np.float32)


def region_weights(spec: str, positions: np.ndarray) -> np.ndarray:
    """(V,) weights from a file (.npy or text, one value per vertex) when ``spec`` names one, else from an
    expression."""
    check_array_shape(positions, "region_weights: positions", ("V", 3))
    path = Path(spec)
    if path.suffix in (".npy", ".txt", ".csv") or path.is_file():
        if not path.is_file():
            raise InputError(f"{path}: graft mask file not found")
        try:
            values = (
                np.load(path, allow_pickle=False)
                if path.suffix == ".npy"
                else np.loadtxt(path, delimiter="," if path.suffix == ".csv" else None)
            )
        except (OSError, ValueError) as error:
            raise InputError(f"{path}: not a readable per-vertex mask ({error})") from None
        values = np.asarray(values, dtype=np.float64).reshape(-1)
        if values.shape[0] != positions.shape[0]:
            raise InputError(f"{path}: {values.shape[0]} values for a mesh of {positions.shape[0]} vertices")
        if not np.all(np.isfinite(values)):
            raise InputError(f"{path}: the mask holds non-finite values")
        return np.clip(values, 0.0, 1.0).astype(np.float32)
    return expression_weights(spec, positions)

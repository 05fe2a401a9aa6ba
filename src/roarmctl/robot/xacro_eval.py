"""The interpreter of a description's xacro expressions (``${...}``, ``$(eval ...)``): an allow-list of Python's syntax.

``Evaluator`` walks one expression's syntax tree and knows only the node types xacro documents for properties
and math: numbers, strings, ``True``/``False``, arithmetic (``+ - * / // % **``), comparisons,
``and``/``or``/``not``, ``a if c else b``, property names, lists/tuples/dicts written out, indexing, the math
functions and constants xacro exposes (``sin``, ``radians``, ``pi``, also as ``math.sin``), ``abs min max round
int float str bool len``, ``dict`` (with keyword arguments too), a few string methods, ``xacro.arg(name)`` and
``xacro.load_yaml(file)`` (served by the caller). Anything else (attribute access, lambda, comprehension,
f-string, a name starting with ``_``, a call of anything not listed) raises ``Refused`` naming it.

Every value an operation makes is bounded as it is made (``Evaluator._made``: its printed size too, however its
parts are shared), and what an operation reads counts (``_operand``), against one expansion's ``Budget``: counts
of work, not seconds, so an exponent bomb (``${9**9**9}``) stops with the same verdict on any machine.
``robot.xacro_safe`` puts this interpreter where xacro would call Python's ``eval``.
"""

from __future__ import annotations

import ast
import itertools
import math
import operator
import re
from collections.abc import Callable
from typing import Any, ClassVar

#: Work one expansion may do (counts, not seconds: the same verdict on a busy machine).
MAX_ELEMENTS = 20_000  # elements evaluated (macro bodies count each time they are expanded)
MAX_EXPRESSIONS = 200_000  # ${...} and $(...) evaluated
MAX_STEPS = 2_000_000  # syntax-tree nodes evaluated (and parts of values sized), over all expressions
MAX_TOKENS = 200_000  # pieces of text, ${...} and $(...) that xacro's lexer cuts the document's texts into
MAX_CHARS = 32 * 1024 * 1024  # characters produced by expressions and held by the elements evaluated
MAX_INCLUDES = 1000  # files included
MAX_MOVES = 5_000_000  # list operations of replacing a macro call by its body (minidom's are linear in the siblings)
#: Values an expression may produce.
MAX_INT_BITS = 256
MAX_STR = 1024 * 1024
MAX_ITEMS = 100_000
#: Characters a list, tuple or mapping may print as (``str()``; xacro prints a value placed in text): a
#: bound on the work of printing or comparing it, however its parts are shared (``[[0]*10**5]*10**5``).
MAX_VALUE_CHARS = 4 * MAX_STR
#: Characters of one ``${...}`` (or ``$(eval ...)``) expression, checked before it is parsed: a long
#: expression costs memory in Python's parser (about 250 bytes a character).
MAX_EXPR_CHARS = 64 * 1024
MATH_FUNCTIONS = ("acos", "acosh", "asin", "asinh", "atan", "atan2", "atanh", "ceil", "copysign", "cos", "cosh",
                  "degrees", "dist", "erf", "erfc", "exp", "expm1", "fabs", "floor", "fmod", "hypot", "isclose",
                  "isfinite", "isinf", "isnan", "ldexp", "log", "log10", "log1p", "log2", "pow", "radians",
                  "remainder", "sin", "sinh", "sqrt", "tan", "tanh", "trunc")
MATH_CONSTANTS = {"pi": math.pi, "e": math.e, "tau": math.tau, "inf": math.inf, "nan": math.nan}
CONSTANTS = {"True": True, "False": False, "None": None, **MATH_CONSTANTS}
#: String methods an expression may call (``'a b'.split(' ')``); their results are bounded like any value.
STR_METHODS = ("split", "rsplit", "strip", "lstrip", "rstrip", "lower", "upper", "title", "capitalize", "replace",
               "startswith", "endswith", "join", "find", "count", "isdigit")


class Refused(Exception):
    """An expression or file that a description may not use; the message says what and why."""


class Budget:
    """Counters of one expansion; ``spend`` raises ``Refused`` past a limit."""

    LIMITS: ClassVar[dict[str, int]] = {"elements": MAX_ELEMENTS, "expressions": MAX_EXPRESSIONS, "steps": MAX_STEPS, "characters": MAX_CHARS,
              "includes": MAX_INCLUDES, "node moves": MAX_MOVES, "tokens": MAX_TOKENS}

    def __init__(self) -> None:
        self.used = dict.fromkeys(self.LIMITS, 0)

    def spend(self, what: str, n: int = 1) -> None:
        """Count ``n`` more of ``what``; Refused past its limit."""
        self.used[what] += n
        if self.used[what] > self.LIMITS[what]:
            raise Refused(f"the description needs more than {self.LIMITS[what]:,} {what} to expand "
                          "(a macro or property that multiplies itself?)")


# --------------------------------------------------------------------------- values
def _int(value: Any = 0) -> int:
    if isinstance(value, str) and len(value) > 80:
        raise Refused("int() of a string of more than 80 characters")
    return int(value)


def _float(value: Any = 0.0) -> float:
    if isinstance(value, str) and len(value) > 80:
        raise Refused("float() of a string of more than 80 characters")
    return float(value)


#: Digits ``round`` may keep or drop (``round(x, n)``, ``|n|``): a float has no digit past 330 (1e308 and 17
#: digits; ``round(1.5, -400)`` is 0.0) and an integer of ``MAX_INT_BITS`` bits 78. ``round(1, -10**9)`` would
#: compute ``10**(10**9)`` before it answers (minutes of work inside one allowed call).
MAX_ROUND_DIGITS = 400


def _round(number: Any, ndigits: Any = None) -> Any:
    if isinstance(ndigits, int) and not -MAX_ROUND_DIGITS <= ndigits <= MAX_ROUND_DIGITS:
        raise Refused(f"round() to more than {MAX_ROUND_DIGITS} digits")
    return round(number, ndigits)


FUNCTIONS: dict[str, Callable[..., Any]] = {
    "abs": abs, "min": min, "max": max, "round": _round, "int": _int, "float": _float, "str": str, "bool": bool,
    "len": len, "dict": dict, **{name: getattr(math, name) for name in MATH_FUNCTIONS},
}
#: The functions that take keyword arguments (``dict(joint_1=0.0, joint_2=0.0)``: Kinova's published gen3.xacro).
KEYWORD_FUNCTIONS = ("dict",)


def check_argument(value: Any) -> Any:
    """An argument of an allowed function, refused past the bounds of a value before the function runs: an
    integer of at most ``MAX_INT_BITS`` bits, a string of at most ``MAX_STR`` characters, a list, tuple or
    mapping of at most ``MAX_ITEMS`` items (a value from ``load_yaml`` was not made by an operation)."""
    if isinstance(value, int) and value.bit_length() > MAX_INT_BITS:
        raise Refused(f"an integer of more than {MAX_INT_BITS} bits")
    if isinstance(value, str) and len(value) > MAX_STR:
        raise Refused(f"a string of more than {MAX_STR:,} characters")
    if isinstance(value, (list, tuple, dict)) and len(value) > MAX_ITEMS:
        raise Refused(f"a list of more than {MAX_ITEMS:,} items")
    return value


def _pow(a: Any, b: Any) -> Any:
    if isinstance(a, int) and isinstance(b, int) and not isinstance(a, bool) and b > 0 and abs(a) > 1:
        if b * (abs(a).bit_length() - 1) > MAX_INT_BITS:
            raise Refused(f"{a} ** {b} is larger than {MAX_INT_BITS} bits")
    result = operator.pow(a, b)
    if isinstance(result, complex):
        raise Refused(f"{a} ** {b} is not a real number")
    return result


def _mul(a: Any, b: Any) -> Any:
    for seq, n in ((a, b), (b, a)):
        if isinstance(seq, (str, list, tuple)) and isinstance(n, int) and not isinstance(n, bool) and (
                len(seq) * max(n, 0) > MAX_STR or (not isinstance(seq, str) and len(seq) * max(n, 0) > MAX_ITEMS)):
            raise Refused(f"a repetition of more than {MAX_ITEMS if not isinstance(seq, str) else MAX_STR:,} items")
    if isinstance(a, int) and isinstance(b, int) and a.bit_length() + b.bit_length() > 2 * MAX_INT_BITS:
        raise Refused(f"a product of more than {MAX_INT_BITS} bits")
    return operator.mul(a, b)


def _mod(a: Any, b: Any) -> Any:
    if isinstance(a, str):
        raise Refused("string formatting with %")
    return operator.mod(a, b)


BINARY: dict[type, Callable[[Any, Any], Any]] = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: _mul, ast.Div: operator.truediv,
    ast.FloorDiv: operator.floordiv, ast.Mod: _mod, ast.Pow: _pow,
}
UNARY: dict[type, Callable[[Any], Any]] = {ast.UAdd: operator.pos, ast.USub: operator.neg, ast.Not: operator.not_}
COMPARE: dict[type, Callable[[Any, Any], Any]] = {
    ast.Eq: operator.eq, ast.NotEq: operator.ne, ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt,
    ast.GtE: operator.ge, ast.In: lambda a, b: a in b, ast.NotIn: lambda a, b: a not in b,
}


# --------------------------------------------------------------------------- the interpreter
#: Nodes that make a new value (not a property's value, a constant or a part of one): checked by ``_made``.
_MAKERS = (ast.BinOp, ast.UnaryOp, ast.Call, ast.List, ast.Tuple, ast.Dict, ast.Subscript)
class Evaluator:
    """Evaluates one expression's syntax tree node by node; only the node types below exist for it.

    ``lookup(name)``: a property's value (KeyError if there is none); ``load_yaml(file)`` and
    ``arg(name)`` serve ``xacro.load_yaml`` and ``xacro.arg``; ``namespace(value, attr)``: the value of
    ``attr`` in an include's namespace or a loaded YAML mapping (KeyError if none).
    """

    def __init__(self, lookup: Callable[[str], Any], budget: Budget, *, load_yaml: Callable[[str], Any] | None = None,
                 arg: Callable[[str], Any] | None = None, namespace: Callable[[Any, str], Any] | None = None) -> None:
        self.lookup = lookup
        self.budget = budget
        self.load_yaml = load_yaml
        self.arg = arg
        self.namespace = namespace

    def __call__(self, text: str) -> Any:
        """The value of the expression ``text`` (the inside of ``${...}``); Refused if it leaves the allow-list."""
        self.budget.spend("expressions")
        if len(text) > MAX_EXPR_CHARS:
            raise Refused(f"an expression of more than {MAX_EXPR_CHARS:,} characters")
        try:
            tree = ast.parse(text.strip(), mode="eval")
        except SyntaxError as exc:
            raise Refused(f"not an expression ({exc.msg})") from None
        except (ValueError, RecursionError, MemoryError):
            raise Refused("not an expression (nested too deeply)") from None
        try:
            value = self.eval(tree.body)
        except RecursionError:
            raise Refused("nested too deeply") from None
        self.budget.spend("characters", self.size(value))  # xacro prints it into the document
        return value

    def size(self, value: Any) -> int:
        """The characters ``value`` prints as (at least 1), computed once per shared part and counted as
        steps; past ``MAX_VALUE_CHARS`` the count stops (the value is refused where it is made)."""
        memo: dict[int, int] = {}

        def walk(v: Any) -> int:
            if isinstance(v, str):
                return len(v) + 2
            if not isinstance(v, (list, tuple, dict)):
                return 24 if not isinstance(v, int) else 2 + v.bit_length() // 3
            if id(v) in memo:
                return memo[id(v)]
            self.budget.spend("steps", 1 + len(v))
            total = 2
            for item in (v.items() if isinstance(v, dict) else v):
                total += walk(item) + 2
                if total > MAX_VALUE_CHARS:
                    break
            memo[id(v)] = total
            return total

        return max(walk(value) - (2 if isinstance(value, str) else 0), 1)

    def _made(self, value: Any) -> Any:
        """A value an operation has just made: refused past its bounds, its size counted as characters."""
        if isinstance(value, str) and len(value) > MAX_STR:
            raise Refused(f"a string of more than {MAX_STR:,} characters")
        if isinstance(value, (list, tuple, dict)):
            if len(value) > MAX_ITEMS:
                raise Refused(f"a list of more than {MAX_ITEMS:,} items")
            if self.size(value) > MAX_VALUE_CHARS:
                raise Refused(f"a value that prints as more than {MAX_VALUE_CHARS:,} characters")
        self.budget.spend("characters", self.size(value))
        return value

    def _operand(self, value: Any) -> Any:
        """A string or container an operation reads (compares, searches, prints): its size counted as
        characters, so that repeating the operation on a large property is bounded like making it."""
        if isinstance(value, (str, list, tuple, dict)):
            self.budget.spend("characters", self.size(value))
        return value

    def eval(self, node: ast.AST) -> Any:
        """The value of one syntax-tree node (by its ``_NodeType`` method; none: refused)."""
        self.budget.spend("steps")
        method = getattr(self, f"_{type(node).__name__}", None)
        if method is None:
            raise Refused(f"{_describe(node)} is not allowed in a description (only numbers, strings, arithmetic, "
                          "comparisons, and/or/not, 'if else', property names and math functions)")
        value = method(node)
        if not (value is None or isinstance(value, (bool, int, float, str, list, tuple, dict))):
            raise Refused(f"a value of type {type(value).__name__}")
        if isinstance(value, int) and value.bit_length() > MAX_INT_BITS:
            raise Refused(f"an integer of more than {MAX_INT_BITS} bits")
        return self._made(value) if isinstance(node, _MAKERS) else value

    def _Constant(self, node: ast.Constant) -> Any:
        return node.value

    def _Name(self, node: ast.Name) -> Any:
        name = node.id
        if name.startswith("_"):
            raise Refused(f"the name '{name}' is not allowed (names starting with '_' are Python's internals)")
        try:
            return self.lookup(name)
        except KeyError:
            pass
        if name in CONSTANTS:
            return CONSTANTS[name]
        if name in FUNCTIONS or name in ("math", "xacro", "load_yaml"):
            raise Refused(f"'{name}' can only be called, as in {name}(...)" if name in FUNCTIONS else
                          f"'{name}' can only be used as in {'math.sin(x)' if name == 'math' else name + '(...)'}")
        raise Refused(f"name '{name}' is not defined (no property of that name)")

    def _BinOp(self, node: ast.BinOp) -> Any:
        op = BINARY.get(type(node.op))
        if op is None:
            raise Refused(f"the operator {type(node.op).__name__} is not allowed")
        left, right = self._operand(self.eval(node.left)), self._operand(self.eval(node.right))
        try:
            return op(left, right)
        except (ValueError, TypeError, OverflowError, ZeroDivisionError) as exc:
            reason = exc.args[-1] if isinstance(exc, OverflowError) and exc.args else exc  # (34, 'Numerical result out of range')
            raise Refused(f"{_describe(node)}: {reason}") from None

    def _UnaryOp(self, node: ast.UnaryOp) -> Any:
        op = UNARY.get(type(node.op))
        if op is None:
            raise Refused(f"the operator {type(node.op).__name__} is not allowed")
        return op(self.eval(node.operand))

    def _BoolOp(self, node: ast.BoolOp) -> Any:
        value: Any = None
        for v in node.values:  # Python's short circuit: and stops at a false value, or at a true one
            value = self.eval(v)
            if isinstance(node.op, ast.And) != bool(value):
                return value
        return value

    def _Compare(self, node: ast.Compare) -> Any:
        left = self.eval(node.left)
        for op_node, right_node in zip(node.ops, node.comparators):
            op = COMPARE.get(type(op_node))
            if op is None:
                raise Refused(f"the comparison {type(op_node).__name__} is not allowed")
            right = self.eval(right_node)
            if not op(self._operand(left), self._operand(right)):
                return False
            left = right
        return True

    def _IfExp(self, node: ast.IfExp) -> Any:
        return self.eval(node.body) if self.eval(node.test) else self.eval(node.orelse)

    def _List(self, node: ast.List) -> Any:
        return [self.eval(e) for e in node.elts]

    def _Tuple(self, node: ast.Tuple) -> Any:
        return tuple(self.eval(e) for e in node.elts)

    def _Dict(self, node: ast.Dict) -> Any:
        if any(k is None for k in node.keys):
            raise Refused("'**' in a dict is not allowed")
        return {self.eval(k): self.eval(v) for k, v in zip(node.keys, node.values)}  # type: ignore[arg-type]

    def _Subscript(self, node: ast.Subscript) -> Any:
        value = self.eval(node.value)
        if not isinstance(value, (list, tuple, str, dict)):
            raise Refused(f"indexing a {type(value).__name__}")
        if isinstance(node.slice, ast.Slice):
            parts = [None if p is None else self.eval(p) for p in (node.slice.lower, node.slice.upper, node.slice.step)]
            if not all(p is None or (isinstance(p, int) and not isinstance(p, bool)) for p in parts):
                raise Refused("a slice of something other than whole numbers")
            if isinstance(value, dict):
                raise Refused("slicing a mapping")
            return value[slice(*parts)]
        key = self.eval(node.slice)
        if isinstance(value, dict) and type(value) is not dict and self.namespace is not None:
            # an include's namespace (xacro's Table): its own properties and its parents', never what its
            # indexing reaches beyond them (xacro's global symbols: Python's builtins, the math module)
            try:
                if not isinstance(key, str):
                    raise KeyError(key)
                return self.namespace(value, key)
            except KeyError:
                raise Refused(f"no property {_describe(node.slice)} in the namespace {_describe(node.value)}") from None
        return value[key]

    def _Attribute(self, node: ast.Attribute) -> Any:
        if node.attr.startswith("_"):
            raise Refused(f"the attribute '{node.attr}' is not allowed (names starting with '_' are Python's internals)")
        if isinstance(node.value, ast.Name) and node.value.id == "math" and not self._is_property("math"):
            if node.attr in MATH_CONSTANTS:
                return MATH_CONSTANTS[node.attr]
            raise Refused(f"math.{node.attr} can only be called" if node.attr in MATH_FUNCTIONS else
                          f"math.{node.attr} is not one of the math functions a description may use")
        value = self.eval(node.value)
        if self.namespace is not None:
            try:
                return self.namespace(value, node.attr)
            except KeyError:
                pass
        raise Refused(f"'.{node.attr}' on a {type(value).__name__} is not allowed (only a YAML mapping's keys and "
                      "an include's namespace)")

    def _Call(self, node: ast.Call) -> Any:
        if any(isinstance(a, ast.Starred) for a in node.args) or any(k.arg is None for k in node.keywords):
            raise Refused("* or ** arguments are not allowed")
        func = self._function(node.func)
        if node.keywords and not any(func is FUNCTIONS[name] for name in KEYWORD_FUNCTIONS):
            raise Refused(f"keyword arguments are allowed only in {', '.join(f'{n}(...)' for n in KEYWORD_FUNCTIONS)}")
        args = [check_argument(self._operand(self.eval(a))) for a in node.args]
        kwargs = {str(k.arg): check_argument(self._operand(self.eval(k.value))) for k in node.keywords}
        try:
            return func(*args, **kwargs)
        except Refused:
            raise
        except (ValueError, TypeError, OverflowError, ZeroDivisionError, MemoryError) as exc:
            raise Refused(f"{ast.unparse(node.func)}(): {exc}") from None

    def _is_property(self, name: str) -> bool:
        try:
            self.lookup(name)
            return True
        except KeyError:
            return False

    def _function(self, node: ast.AST) -> Callable[..., Any]:
        if isinstance(node, ast.Attribute) and node.attr in STR_METHODS and not (
                isinstance(node.value, ast.Name) and node.value.id in ("math", "xacro") and not self._is_property(node.value.id)):
            owner = self._operand(self.eval(node.value))
            if isinstance(owner, str):
                return _str_method(owner, node.attr)
        if isinstance(node, ast.Name) and not self._is_property(node.id):
            if node.id in FUNCTIONS:
                return FUNCTIONS[node.id]
            if node.id == "load_yaml" and self.load_yaml is not None:
                return self.load_yaml
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and not self._is_property(node.value.id):
            owner, attr = node.value.id, node.attr
            if owner == "math" and attr in MATH_FUNCTIONS:
                return FUNCTIONS[attr]
            if owner == "xacro" and attr == "load_yaml" and self.load_yaml is not None:
                return self.load_yaml
            if owner == "xacro" and attr == "arg" and self.arg is not None:
                return self.arg
        raise Refused(f"calling {_describe(node)} is not allowed (functions: math functions, "
                      f"{', '.join(n for n in FUNCTIONS if n not in MATH_FUNCTIONS)}, xacro.arg, xacro.load_yaml)")


def no_properties(name: str) -> Any:
    """The lookup of an evaluation without properties (a YAML unit tag's expression)."""
    raise KeyError(name)


def _str_method(text: str, name: str) -> Callable[..., Any]:
    """``text.name`` with its result's size checked BEFORE it is built (``replace`` and ``join`` can grow)."""
    method = getattr(text, name)
    if name in ("split", "rsplit"):
        def split(sep: Any = None, maxsplit: Any = -1) -> list[str]:
            if isinstance(sep, str) and sep and isinstance(maxsplit, int):  # the pieces, counted before they are made
                pieces = text.count(sep) + 1 if maxsplit < 0 else min(text.count(sep), maxsplit) + 1
            elif sep is None and isinstance(maxsplit, int):
                pieces = sum(1 for _ in itertools.islice(re.finditer(r"\S+", text), MAX_ITEMS + 1))
            else:
                pieces = 0  # the method refuses the arguments
            if pieces > MAX_ITEMS:
                raise Refused(f"a list of more than {MAX_ITEMS:,} items")
            return method(sep, maxsplit)
        return split
    if name == "replace":
        def replace(old: Any, new: Any, count: int = -1) -> str:
            if not isinstance(old, str) or not isinstance(new, str):
                raise Refused("str.replace() takes strings")
            n = text.count(old) if old else len(text) + 1
            if count >= 0:
                n = min(n, count)
            if len(text) + n * (len(new) - len(old)) > MAX_STR:
                raise Refused(f"a string of more than {MAX_STR:,} characters")
            return text.replace(old, new, count)
        return replace
    if name == "join":
        def join(items: Any) -> str:
            if not isinstance(items, (list, tuple)) or not all(isinstance(i, str) for i in items):
                raise Refused("str.join() takes a list of strings")
            if sum(map(len, items)) + len(text) * max(len(items) - 1, 0) > MAX_STR:
                raise Refused(f"a string of more than {MAX_STR:,} characters")
            return text.join(items)
        return join
    return method


def _describe(node: ast.AST) -> str:
    try:
        text = ast.unparse(node)
    except Exception:  # noqa: BLE001 - only for the message
        text = type(node).__name__
    kind = {"Lambda": "a lambda", "ListComp": "a list comprehension", "GeneratorExp": "a generator",
            "DictComp": "a dict comprehension", "SetComp": "a set comprehension", "JoinedStr": "an f-string",
            "NamedExpr": "':='", "Starred": "'*'", "Set": "a set", "Await": "await", "Yield": "yield"}.get(type(node).__name__)
    short = text if len(text) <= 40 else text[:37] + "..."
    return f"{kind} ('{short}')" if kind else f"'{short}'"

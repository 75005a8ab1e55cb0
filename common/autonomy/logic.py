"""The helm's mission variables, logic conditions and hierarchical modes (pHelmIvP's
`condition = ...` and `set MODE = ...`, the MOOS-IvP helm documentation, Benjamin et al.).

A variable holds a string or a number. A condition is `NAME op VALUE` with op one of `==`
(or `=`), `!=`, `<`, `<=`, `>`, `>=`, joined by `and` and `or` (`and` binds tighter; no
parentheses). Numbers compare as numbers when both sides are numbers, otherwise values compare
as exact strings; a condition on a variable that has no value is false, as in MOOS-IvP.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

Value = str | float

_ATOM = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(==|!=|<=|>=|=|<|>)\s*(\"[^\"]*\"|'[^']*'|[^\s]+)\s*$")


def as_value(raw) -> Value:
    """A TOML or poked value as a variable value: booleans as "true"/"false", numbers as float."""
    if isinstance(raw, bool):
        return "true" if raw else "false"
    if isinstance(raw, int | float):
        return float(raw)
    text = str(raw)
    try:
        return float(text)
    except ValueError:
        return text


def format_value(value: Value) -> str:
    return f"{value:g}" if isinstance(value, float) else value


@dataclass(frozen=True)
class Atom:
    name: str
    op: str
    value: Value

    def holds(self, variables: Mapping[str, Value]) -> bool:
        if self.name not in variables:
            return False
        left, right = variables[self.name], self.value
        if isinstance(left, float) and isinstance(right, float):
            return {
                "==": left == right,
                "!=": left != right,
                "<": left < right,
                "<=": left <= right,
                ">": left > right,
                ">=": left >= right,
            }[self.op]
        left, right = format_value(left), format_value(right)
        if self.op == "==":
            return left == right
        if self.op == "!=":
            return left != right
        return False  # an order between strings is never true


@dataclass(frozen=True)
class Condition:
    """A parsed condition: alternatives (or) of conjunctions (and) of atoms."""

    text: str
    alternatives: tuple[tuple[Atom, ...], ...]

    def holds(self, variables: Mapping[str, Value]) -> bool:
        return any(all(atom.holds(variables) for atom in conj) for conj in self.alternatives)

    def names(self) -> set[str]:
        return {atom.name for conj in self.alternatives for atom in conj}


def check_conditions(texts: list[str]) -> list[str]:
    """The texts unchanged once each parses (a pydantic validator of every `condition` list)."""
    for text in texts:
        parse_condition(text)
    return texts


def parse_condition(text: str) -> Condition:
    """Parse a condition; ValueError naming the part that is not `NAME op VALUE`."""
    alternatives = []
    for part in re.split(r"\s+or\s+", text.strip()):
        atoms = []
        for piece in re.split(r"\s+and\s+", part):
            match = _ATOM.match(piece)
            if match is None:
                raise ValueError(f"{piece.strip()!r} is not 'NAME op VALUE' (op one of == != < <= > >=)")
            name, op, raw = match.groups()
            if raw[0] in "\"'":
                value: Value = raw[1:-1]
            else:
                value = as_value(raw)
            atoms.append(Atom(name, "==" if op == "=" else op, value))
        alternatives.append(tuple(atoms))
    return Condition(text, tuple(alternatives))


def all_hold(conditions: tuple[Condition, ...], variables: Mapping[str, Value]) -> bool:
    """Several conditions are ANDed, as pHelmIvP's repeated `condition` lines."""
    return all(c.holds(variables) for c in conditions)


@dataclass(frozen=True)
class ModeRule:
    """`set VAR = VALUE { VAR = PARENT; conditions } ELSE`: applies while VAR is unset (no parent)
    or equals PARENT, and appends VALUE (or ELSE, if given) to it after a ':'."""

    variable: str
    value: str
    parent: str | None
    conditions: tuple[Condition, ...]
    otherwise: str | None


def evaluate_modes(rules: tuple[ModeRule, ...], variables: Mapping[str, Value]) -> dict[str, str]:
    """The mode variables' values, built from scratch in rule order from `variables` (children
    are declared after their parents); a mode variable no rule sets is "" (no mode)."""
    modes: dict[str, str] = {rule.variable: "" for rule in rules}
    for rule in rules:
        current = modes[rule.variable]
        if current != (rule.parent or ""):
            continue
        chosen = rule.value if all_hold(rule.conditions, variables) else rule.otherwise
        if chosen is not None:
            modes[rule.variable] = f"{current}:{chosen}" if current else chosen
    return modes

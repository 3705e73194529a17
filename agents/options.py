"""Options declared once, next to their fields, and checked by one validator.

Every option of the agent and of a run is a dataclass field made with ``option``:
its type is the field's annotation, and its range or choices sit in the field's
metadata. ``check`` (called by each dataclass's ``__post_init__``) and ``from_dict``
(which builds nested dataclasses from a Hydra config, refusing unknown keys) read
those declarations, so no option is checked by hand and every message has the same
form. One key rule: a field is named by its key in the run's config, which is the
``KEY`` of the dataclass that declares it plus the field's name
(``agent.networks.latent_dim``, ``agent.lr``, ``train.steps``, ``seed``), whether
the dataclass was built from a config or directly in Python.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from typing import Any, TypeVar

T = TypeVar("T")


class OptionError(ValueError):
    """A bad option, reported in one line before any work starts."""


def option(default: Any = dataclasses.MISSING, *, factory: Any = dataclasses.MISSING,
           low: float | None = None, high: float | None = None, low_open: bool = False,
           high_open: bool = False, choices: tuple | None = None) -> Any:
    """A dataclass field with its valid values: ``low``/``high`` bounds (closed unless
    ``*_open``) or a tuple of ``choices``."""
    metadata = {"low": low, "high": high, "low_open": low_open, "high_open": high_open,
                "choices": choices}
    if factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=factory, metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def key(cls: type, name: str) -> str:
    """The config key of field ``name``: the ``KEY`` of the class that declares it."""
    owner = next((c for c in cls.__mro__ if name in c.__dict__.get("__annotations__", {})), cls)
    prefix = getattr(owner, "KEY", "")
    return f"{prefix}.{name}" if prefix else name


def show(value: Any) -> str:
    """A value as YAML writes it (true, false, null)."""
    if isinstance(value, bool) or value is None:
        return {True: "true", False: "false", None: "null"}[value]
    return str(value)


_KINDS = {int: ("an integer", lambda v: isinstance(v, int) and not isinstance(v, bool)),
          float: ("a number", lambda v: isinstance(v, (int, float)) and not isinstance(v, bool)),
          bool: ("true or false", lambda v: isinstance(v, bool)),
          str: ("a string", lambda v: isinstance(v, str))}


def _check_type(name: str, expected: Any, value: Any) -> None:
    if typing.get_origin(expected) in (typing.Union, types.UnionType):
        options = typing.get_args(expected)
        if value is None and type(None) in options:
            return
        allowed = [t for t in options if t is not type(None)]
        if any(t in _KINDS and _KINDS[t][1](value) for t in allowed):
            return
        if len(allowed) > 1 and not isinstance(value, Mapping):  # none of several kinds fits
            kinds = ["a mapping" if typing.get_origin(t) is dict else _KINDS[t][0] for t in allowed]
            raise OptionError(f"{name} must be {' or '.join(kinds)}, got {value!r}")
        expected = allowed[0]
    if typing.get_origin(expected) is dict:
        if not isinstance(value, Mapping):
            raise OptionError(f"{name} must be a mapping, got {value!r}")
        _, item = typing.get_args(expected)
        for k, v in value.items():
            _check_type(f"{name}.{k}", item, v)
        return
    if expected in _KINDS:
        what, ok = _KINDS[expected]
        if not ok(value):
            raise OptionError(f"{name} must be {what}, got {value!r}")


def _check_range(name: str, value: Any, meta: Mapping[str, Any]) -> None:
    choices = meta.get("choices")
    if choices is not None:
        # 1 == True in Python: a choice matches only a value of the same type
        if not any(value == c and type(value) is type(c) for c in choices):
            raise OptionError(f"{name}={value!r}; valid: {', '.join(show(c) for c in choices)}")
        return
    low, high = meta.get("low"), meta.get("high")
    if value is None or (low is None and high is None):
        return
    too_low = low is not None and (value <= low if meta["low_open"] else value < low)
    too_high = high is not None and (value >= high if meta["high_open"] else value > high)
    if not (too_low or too_high):
        return
    if low is not None and high is not None:
        span = f"in {'(' if meta['low_open'] else '['}{low}, {high}{')' if meta['high_open'] else ']'}"
    elif low is not None:
        span = f"{'>' if meta['low_open'] else '>='} {low}"
    else:
        span = f"{'<' if meta['high_open'] else '<='} {high}"
    raise OptionError(f"{name} must be {span}, got {value}")


def check(instance: Any) -> None:
    """Type, range and choices of every field of a dataclass instance, as declared."""
    cls = type(instance)
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(instance):
        if not f.init:
            continue
        value = getattr(instance, f.name)
        if dataclasses.is_dataclass(hints[f.name]):
            if not isinstance(value, hints[f.name]):
                raise OptionError(f"{key(cls, f.name)} must be of type {hints[f.name].__name__}, "
                                  f"got {value!r}")
            continue  # checked by its own __post_init__
        name = key(cls, f.name)
        _check_type(name, hints[f.name], value)
        _check_range(name, value, f.metadata)


def unknown(name: str, valid: typing.Iterable[str]) -> OptionError:
    return OptionError(f"unknown option {name}; valid: {', '.join(sorted(valid))}")


def from_dict(cls: type[T], data: Mapping[str, Any]) -> T:
    """Build ``cls`` from nested plain data (a Hydra config section): unknown keys are
    refused, nested dataclasses built the same way, and every value checked."""
    if not isinstance(data, Mapping):
        raise OptionError(f"{getattr(cls, 'KEY', cls.__name__)} must be a mapping, got {data!r}")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls) if f.init}
    kwargs = {}
    for name, value in data.items():
        if name not in names:
            prefix = getattr(cls, "KEY", "")
            raise unknown(f"{prefix}.{name}" if prefix else repr(name), names)
        if dataclasses.is_dataclass(hints[name]):
            if not isinstance(value, hints[name]):  # built already, with its own rule
                value = from_dict(hints[name], value)
        else:
            _check_type(key(cls, name), hints[name], value)  # before __post_init__ compares
        kwargs[name] = value
    required = [f.name for f in dataclasses.fields(cls) if f.init and f.name not in kwargs
                and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING]
    if required:
        raise OptionError(f"{key(cls, required[0])} is required (no default)")
    return cls(**kwargs)

"""ROS interface types from strings, and messages to/from plain data (YAML, JSON, CSV).

rosidl_runtime_py (what `ros2` uses for this) is not published as a wheel, so this is the
small subset the CLI needs: resolve `pkg/msg/Type`, fill a message from a dict with errors
that name the field, and turn a message into ordered plain data.
"""
from __future__ import annotations

import array
import importlib
from collections.abc import Iterator
from typing import Any

import numpy as np
import yaml

KINDS = ("msg", "srv", "action")


class InterfaceError(ValueError):
    """An interface type string or field value that cannot be used; the message says why."""


def resolve_type(type_name: str, kind: str = "msg") -> type:
    """Import the Python class of `pkg/<kind>/Type` (or `pkg/Type`, taking `kind`)."""
    parts = type_name.strip().split("/")
    if len(parts) == 2:
        parts = [parts[0], kind, parts[1]]
    if len(parts) != 3 or not all(parts) or parts[1] not in KINDS:
        raise InterfaceError(f"'{type_name}' is not an interface type: expected 'package/{kind}/Type'")
    package, found_kind, name = parts
    if found_kind != kind:
        raise InterfaceError(f"'{type_name}' is a {found_kind}, a {kind} type is needed here")
    try:
        module = importlib.import_module(f"{package}.{kind}")
    except ImportError:
        raise InterfaceError(f"unknown interface package '{package}' (is it built and installed?)") from None
    cls = getattr(module, name, None)
    if cls is None:
        raise InterfaceError(f"package '{package}' has no {kind} '{name}'")
    return cls


def type_name_of(cls_or_msg: Any) -> str:
    """`pkg/msg/Type` of a message class or instance."""
    cls = cls_or_msg if isinstance(cls_or_msg, type) else type(cls_or_msg)
    package, kind = cls.__module__.split(".")[:2]
    return f"{package}/{kind}/{cls.__name__}"


def is_message(value: Any) -> bool:
    return hasattr(value, "get_fields_and_field_types") and not isinstance(value, type)


def to_plain(value: Any, truncate: int | None = None) -> Any:
    """Ordered plain data (dicts, lists, numbers, strings) for a message or field value.

    Arrays longer than `truncate` keep their first elements and end in '...', like
    `ros2 topic echo --truncate-length`.
    """
    if is_message(value):
        return {field: to_plain(getattr(value, field), truncate)
                for field in value.get_fields_and_field_types()}
    if isinstance(value, (bytes, bytearray)):
        value = list(value)
    if isinstance(value, (list, tuple, array.array, np.ndarray)):
        items = value.tolist() if isinstance(value, (np.ndarray, array.array)) else list(value)
        if truncate is not None and len(items) > truncate:
            return [to_plain(v, truncate) for v in items[:truncate]] + ["..."]
        return [to_plain(v, truncate) for v in items]
    if isinstance(value, np.generic):
        return value.item()
    return value


def to_yaml(msg: Any, truncate: int | None = None) -> str:
    """YAML as `ros2 topic echo` prints it."""
    return yaml.safe_dump(to_plain(msg, truncate), default_flow_style=False, sort_keys=False,
                          allow_unicode=True, width=1_000_000)


def flatten(value: Any) -> Iterator[Any]:
    """Leaf values in field order, for `--csv` output."""
    if isinstance(value, dict):
        for item in value.values():
            yield from flatten(item)
    elif isinstance(value, list):
        for item in value:
            yield from flatten(item)
    else:
        yield value


def _element_class(msg: Any, field: str) -> type | None:
    """The message class of a sequence-of-messages field, or None for primitive sequences."""
    index = list(msg.get_fields_and_field_types()).index(field)
    slot = msg.SLOT_TYPES[index]
    element = getattr(slot, "value_type", None)
    namespaces = getattr(element, "namespaces", None)
    if not namespaces:
        return None
    return getattr(importlib.import_module(".".join(namespaces)), element.name)


INTEGER_RANGES = {f"{sign}int{bits}": ((0, 2**bits - 1) if sign else (-(2**(bits - 1)), 2**(bits - 1) - 1))
                  for sign in ("", "u") for bits in (8, 16, 32, 64)}
INTEGER_RANGES.update({"octet": (0, 255), "char": (0, 255)})


def _coerce(value: Any, type_str: str, path: str) -> Any:
    """Check (and widen int to float) one primitive value against its rosidl type name.

    The generated setters only check types when ROS_PYTHON_CHECK_FIELDS=1, so a wrong
    value would otherwise surface as an opaque error deep inside publish().
    """
    base = type_str.split("<", 1)[0]
    if base in ("double", "float"):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InterfaceError(f"{path}: cannot set {value!r} on a field of type '{type_str}' (a number is needed)")
        return float(value)
    if base in INTEGER_RANGES:
        low, high = INTEGER_RANGES[base]
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise InterfaceError(f"{path}: cannot set {value!r} on a field of type '{type_str}' "
                                 f"(an integer in [{low}, {high}] is needed)")
        return value
    if base == "boolean" and not isinstance(value, bool):
        raise InterfaceError(f"{path}: cannot set {value!r} on a field of type 'boolean' (true or false)")
    if base in ("string", "wstring") and not isinstance(value, str):
        raise InterfaceError(f"{path}: cannot set {value!r} on a field of type '{type_str}' (a string is needed)")
    return value


def fill(msg: Any, values: Any, path: str = "") -> Any:
    """Set the fields of `msg` from a dict (as parsed from YAML); return `msg`."""
    where = path or type_name_of(msg)
    if values is None:
        return msg
    if not isinstance(values, dict):
        raise InterfaceError(f"{where}: expected a mapping of field names, got {values!r}")
    fields = msg.get_fields_and_field_types()
    for key, value in values.items():
        field_path = f"{path}.{key}" if path else key
        if key not in fields:
            raise InterfaceError(f"{type_name_of(msg)} has no field '{key}' (fields: {', '.join(fields) or 'none'})")
        current = getattr(msg, key)
        type_str = fields[key]
        if is_message(current):
            fill(current, value, field_path)
            continue
        element_cls = _element_class(msg, key)
        if type_str.startswith("sequence<") or type_str.endswith("]"):
            if not isinstance(value, list):
                raise InterfaceError(f"{field_path}: expected a list for '{type_str}', got {value!r}")
            element_type = type_str.removeprefix("sequence<").split(",")[0].rstrip(">").split("[")[0]
            value = [fill(element_cls(), item, f"{field_path}[{i}]") if element_cls is not None
                     else _coerce(item, element_type, f"{field_path}[{i}]") for i, item in enumerate(value)]
        else:
            value = _coerce(value, type_str, field_path)
        try:
            setattr(msg, key, value)
        except (AssertionError, TypeError, ValueError) as exc:
            raise InterfaceError(f"{field_path}: cannot set {value!r} on a field of type '{type_str}' ({exc})") from None
    return msg


def parse_values(text: str) -> Any:
    """Parse the YAML of a request/goal/message given on the command line."""
    try:
        return yaml.safe_load(text) if text.strip() else {}
    except yaml.YAMLError as exc:
        raise InterfaceError(f"malformed YAML: {exc}".replace("\n", " ")) from None

"""Configs: one dataclass tree per command, loaded from YAML, every field with a default.

Usage::

    @dataclass
    class OptimConfig:
        lr: float = 1e-3  # Adam learning rate

    @dataclass
    class TrainConfig:
        iters: int = 1000  # training iterations
        optim: OptimConfig = field(default_factory=OptimConfig)

    cfg = load_config(TrainConfig, "my.yaml", overrides={"iters": 10})
    save_config(cfg, run_dir / "config.yaml")
"""

from __future__ import annotations

import dataclasses
import math
import os
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from mesh2tex.errors import InputError
from mesh2tex.io.atomic import write_text
from mesh2tex.limits import check_config_value, short

T = TypeVar("T")

# The widest layer a config may ask for: far above any trained model (the paper's widest is 512), far
# below a width whose weights would not fit in memory.
MAX_CHANNELS = 4096


def config_to_dict(cfg) -> dict[str, Any]:
    """A plain dict (nested) of a config dataclass."""
    return dataclasses.asdict(cfg)


def config_from_dict(cls: type[T], data: dict[str, Any] | None, where: str = "config", base: T | None = None) -> T:
    """Build ``cls`` from a nested dict; unknown keys, wrong types and values a config's own checks
    (its ``__post_init__``, raising ValueError) refuse are user errors naming the key.

    The keys ``data`` leaves out keep the values of ``base`` (None: the class's defaults). A nested
    config starts from its field's default, so that a field such as
    ``transfer: TransferConfig = field(default_factory=lambda: TransferConfig(scales=2))`` keeps
    ``scales`` 2 when the YAML sets only other keys of ``transfer``."""
    data = dict(data or {})
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name not in data:
            continue
        value = data.pop(f.name)
        hint = hints[f.name]
        if dataclasses.is_dataclass(hint):
            if not isinstance(value, dict):
                raise InputError(f"{where}: '{f.name}' must be a mapping")
            value = config_from_dict(
                hint, value, f"{where}.{f.name}", getattr(base, f.name) if base is not None else _field_default(f)
            )
        else:
            value = _coerce(value, hint, f"{where}.{f.name}")
            check_config_value(f.name, value, f"{where}.{f.name}")  # sizes and angles: the same range in every command
        kwargs[f.name] = value
    if data:
        # A config class may name keys that moved (MOVED_KEYS: old key -> its new dotted place).
        moved = getattr(cls, "MOVED_KEYS", {})
        if any(key in moved for key in data):
            places = ", ".join(f"{key} -> {moved[key]}" for key in sorted(data, key=str) if key in moved)
            raise InputError(f"{where}: key(s) moved: {places}")
        known = ", ".join(f.name for f in dataclasses.fields(cls))
        raise InputError(f"{where}: unknown key(s) {short(sorted(str(k) for k in data), 200)}; known keys: {known}")
    try:
        return cls(**kwargs) if base is None else dataclasses.replace(base, **kwargs)
    except (ValueError, TypeError) as error:
        raise InputError(f"{where}: {error}") from None


def _field_default(f: dataclasses.Field):
    """The default of a dataclass field (a new one from its factory), None when it has none."""
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None if f.default is dataclasses.MISSING else f.default


def _coerce(value, hint, where: str):
    """``value`` as type ``hint``: floats from ints and numeric strings ("1e-3", which YAML 1.1 reads as
    a string), finite only; ints (64-bit), strings and bools as they are; list elements each coerced."""
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        return _coerce(value, inner[0], where) if len(inner) == 1 else value
    if hint is float:
        if isinstance(value, str):
            try:
                value = float(value.strip())
            except ValueError:
                raise InputError(f"{where}: expected a number, got {short(value)}") from None
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise InputError(f"{where}: expected a number, got {short(value)}")
        try:
            number = float(value)
        except OverflowError:  # an integer beyond any float
            number = math.inf
        if not math.isfinite(number):
            raise InputError(f"{where}: expected a finite number, got {short(value)}")
        return number
    if hint in (int, str, bool):
        if not isinstance(value, hint) or (hint is int and isinstance(value, bool)):
            raise InputError(f"{where}: expected {hint.__name__}, got {short(value)}")
        if hint is int and not -(2**63) <= value < 2**63:  # seeds and counts alike: beyond 64 bits is a typo
            raise InputError(f"{where}: {value} is out of range (a 64-bit integer)")
        return value
    if origin in (list, tuple):
        if not isinstance(value, (list, tuple)):
            raise InputError(f"{where}: expected a list, got {short(value)}")
        if args and args[-1] is not Ellipsis and origin is tuple and len(args) != len(value):
            raise InputError(f"{where}: expected {len(args)} values, got {len(value)}")
        if args:
            element = (lambda i: args[0]) if origin is list or args[-1] is Ellipsis else (lambda i: args[i])
            value = [_coerce(v, element(i), f"{where}[{i}]") for i, v in enumerate(value)]
        return list(value) if origin is list else tuple(value)
    return value


def check_fields(
    cfg,
    *,
    at_least: dict[str, float] | None = None,
    positive: tuple[str, ...] = (),
    between: dict[str, tuple[float, float]] | None = None,
) -> None:
    """Range checks for a config's ``__post_init__``: ValueError naming the first field out of range.

    ``at_least`` maps a field to its lowest value, ``positive`` lists fields that must be > 0,
    ``between`` maps a field to its closed interval (a list field: every element).
    """

    def values(name):
        value = getattr(cfg, name)
        return list(value) if isinstance(value, (list, tuple)) else [value]

    for name, low in (at_least or {}).items():
        if any(v < low for v in values(name)):
            raise ValueError(f"{name} must be at least {low:g}, got {short(getattr(cfg, name))}")
    for name in positive:
        if any(not v > 0 for v in values(name)):
            raise ValueError(f"{name} must be positive, got {short(getattr(cfg, name))}")
    for name, (low, high) in (between or {}).items():
        if any(not low <= v <= high for v in values(name)):
            raise ValueError(f"{name} must be in [{low:g}, {high:g}], got {short(getattr(cfg, name))}")


# A config is a few hundred lines: more is not a config, and an alias expanded more often than this
# (a 500-byte "billion laughs" document) is refused before any of it is walked.
MAX_CONFIG_BYTES = 1_000_000
MAX_CONFIG_NODES = 100_000


def read_yaml(path: Path):
    """The YAML document at ``path`` (yaml.safe_load), refused (InputError) when the file is larger than
    :data:`MAX_CONFIG_BYTES` or its aliases expand to more than :data:`MAX_CONFIG_NODES` values."""
    size = path.stat().st_size
    if size > MAX_CONFIG_BYTES:
        raise InputError(f"{path}: {size} bytes is too large for a config (at most {MAX_CONFIG_BYTES})")
    loader = yaml.SafeLoader(path.read_text(encoding="utf-8"))
    try:
        node = loader.get_single_node()
    finally:
        loader.dispose()
    if node is None:
        return None
    count, stack = 0, [node]
    while stack:  # every value the document holds once its aliases are expanded, stopping at the limit
        current = stack.pop()
        count += 1
        if count > MAX_CONFIG_NODES:
            raise InputError(
                f"{path}: its aliases expand to more than {MAX_CONFIG_NODES} values; write the config out without "
                f"nested aliases"
            )
        if isinstance(current, yaml.SequenceNode):
            stack.extend(current.value)
        elif isinstance(current, yaml.MappingNode):
            for key, value in current.value:
                stack.extend((key, value))
    constructor = yaml.SafeLoader("")
    try:
        return constructor.construct_document(node)
    finally:
        constructor.dispose()


def load_config(cls: type[T], path: str | os.PathLike | None = None, overrides: dict[str, Any] | None = None) -> T:
    """Defaults of ``cls``, then the YAML file at ``path`` (if given), then ``overrides``.

    ``overrides`` maps dotted keys (``"optim.lr"``) to values; ``None`` values are ignored so that
    unset command-line flags keep the file's value.
    """
    data: dict[str, Any] = {}
    if path is not None:
        path = Path(path)
        if not path.is_file():
            raise InputError(f"{path}: config file not found")
        try:
            loaded = read_yaml(path)
        except UnicodeDecodeError as error:
            raise InputError(f"{path}: not UTF-8 text (byte {error.start}); save the config as UTF-8") from None
        except yaml.YAMLError as error:
            raise InputError(f"{path}: not valid YAML ({error.__class__.__name__})") from None
        except RecursionError:
            raise InputError(f"{path}: nested too deeply to be a config") from None
        if loaded is not None and not isinstance(loaded, dict):
            raise InputError(f"{path}: the config must be a mapping")
        data = loaded or {}
    for key, value in (overrides or {}).items():
        if value is None:
            continue
        node = data
        *parents, leaf = key.split(".")
        for part in parents:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise InputError(f"{path or 'config'}: '{part}' must be a mapping")
        node[leaf] = value
    return config_from_dict(cls, data, str(path) if path else "config")


def config_yaml(cfg) -> str:
    """The config as YAML text, its fields in their order (what ``--print-config`` prints)."""
    return yaml.safe_dump(config_to_dict(cfg), sort_keys=False)


def save_config(cfg, path: str | os.PathLike) -> None:
    """Write the resolved config as YAML (atomically)."""
    write_text(path, config_yaml(cfg))

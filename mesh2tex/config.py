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
import os
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from mesh2tex.errors import UserError
from mesh2tex.io.atomic import write_text

T = TypeVar("T")


def config_to_dict(cfg) -> dict[str, Any]:
    """A plain dict (nested) of a config dataclass."""
    return dataclasses.asdict(cfg)


def config_from_dict(cls: type[T], data: dict[str, Any] | None, where: str = "config") -> T:
    """Build ``cls`` from a nested dict; unknown keys and wrong types are user errors naming the key."""
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
                raise UserError(f"{where}: '{f.name}' must be a mapping")
            value = config_from_dict(hint, value, f"{where}.{f.name}")
        else:
            value = _coerce(value, hint, f"{where}.{f.name}")
        kwargs[f.name] = value
    if data:
        known = ", ".join(f.name for f in dataclasses.fields(cls))
        raise UserError(f"{where}: unknown key(s) {sorted(data)}; known keys: {known}")
    return cls(**kwargs)


def _coerce(value, hint, where: str):
    origin = typing.get_origin(hint)
    if hint is float and isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    if hint in (int, str, bool):
        if not isinstance(value, hint) or (hint is int and isinstance(value, bool)):
            raise UserError(f"{where}: expected {hint.__name__}, got {value!r}")
        return value
    if origin in (list, tuple):
        if not isinstance(value, (list, tuple)):
            raise UserError(f"{where}: expected a list, got {value!r}")
        return list(value) if origin is list else tuple(value)
    return value


def load_config(cls: type[T], path: str | os.PathLike | None = None, overrides: dict[str, Any] | None = None) -> T:
    """Defaults of ``cls``, then the YAML file at ``path`` (if given), then ``overrides``.

    ``overrides`` maps dotted keys (``"optim.lr"``) to values; ``None`` values are ignored so that
    unset command-line flags keep the file's value.
    """
    data: dict[str, Any] = {}
    if path is not None:
        path = Path(path)
        if not path.is_file():
            raise UserError(f"{path}: config file not found")
        try:
            loaded = yaml.safe_load(path.read_text())
        except yaml.YAMLError as error:
            raise UserError(f"{path}: not valid YAML ({error.__class__.__name__})") from None
        if loaded is not None and not isinstance(loaded, dict):
            raise UserError(f"{path}: the config must be a mapping")
        data = loaded or {}
    for key, value in (overrides or {}).items():
        if value is None:
            continue
        node = data
        *parents, leaf = key.split(".")
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    return config_from_dict(cls, data, str(path) if path else "config")


def save_config(cfg, path: str | os.PathLike) -> None:
    """Write the resolved config as YAML (atomically)."""
    write_text(path, yaml.safe_dump(config_to_dict(cfg), sort_keys=False))

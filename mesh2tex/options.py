"""The command-line options every command shares, built without importing torch.

``mesh2tex --help`` and ``mesh2tex CMD --help`` read only the stages' ``options.py`` modules, which
import this module and nothing heavy; a command's ``run()`` imports the rest. So that ``--help`` can
still show the defaults of a config that lives beside torch code (``TrainGanConfig`` in
``train/gan.py``, ``GeneratorConfig`` in ``mesh2tex/nn/generator.py``), :func:`static_defaults` reads
them from the source with ``ast`` (literal values, nested configs, names of module constants);
``tests/test_cli.py`` checks that they equal the defaults the imported classes give.

* :class:`Parser` prints a bad option as one line, ``mesh2tex: error: ...``, and exits with status 2.
* :class:`HelpFormatter` appends ``(default: X)`` to every option's help: the argparse default, or for
  a flag that overrides a config field (:meth:`ConfigOptions.add`) that field's default.
* :class:`ConfigOptions` declares which flag overrides which config field; :func:`config_overrides`
  gives a command the overrides of every flag it declared.
* :func:`add_out` and :func:`add_device`: ``--out DIR`` and ``--device auto|cpu|cuda`` alike everywhere;
  :func:`add_overwrite`: ``--overwrite`` on every command that writes; :func:`add_checkpoint`:
  ``--checkpoint NAME|PATH`` wherever a generator is read; :func:`add_texture_format`:
  ``--texture-format png|jpeg|webp`` on every command that writes a GLB; :func:`parse_seeds`: the
  ``--seeds`` lists and ranges (``0-7``, ``0,2,5-9``).
* :func:`renamed`: an old spelling of a flag keeps working, hidden from ``--help``, and says once
  ``mesh2tex: warning: --gan is renamed --checkpoint`` (:func:`mesh2tex.errors.warning`, the one-line form
  of every warning the commands give; ``mesh2tex/cli.py`` shows Python warnings the same way).
"""

from __future__ import annotations

import argparse
import ast
import copy
import functools
import sys
from pathlib import Path

from mesh2tex.errors import warning

DEVICES = ("auto", "cpu", "cuda")


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line: ``mesh2tex: error: <what>; see 'PROG --help'`` (exit 2),
    and which warns when an old spelling of a flag (:func:`renamed`) is used."""

    def parse_known_args(self, args=None, namespace=None):
        words = sys.argv[1:] if args is None else list(args)
        for action in self._actions:
            for old in getattr(action, "renamed_from", ()):
                if any(word == old or word.startswith(old + "=") for word in words):
                    warning(f"{old} is renamed {action.option_strings[0]}")
        return super().parse_known_args(args, namespace)

    def error(self, message: str):
        for action in self._actions:  # name an option as its help does, without its hidden aliases
            hidden = getattr(action, "hidden_aliases", ())
            if hidden:
                message = message.replace(
                    "/".join(action.option_strings), "/".join(s for s in action.option_strings if s not in hidden)
                )
        from mesh2tex.errors import one_line

        print(f"mesh2tex: error: {one_line(message)}; see '{self.prog} --help'", file=sys.stderr)
        sys.exit(2)


class HelpFormatter(argparse.HelpFormatter):
    """Help that shows every option's default and hides the aliases kept for old scripts."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if action.default is argparse.SUPPRESS or "default" in text:  # written by hand
            return text
        source = getattr(action, "config_source", None)
        shown = show_default(config_default(*source) if source else action.default)
        return text if shown is None else f"{text} (default: {shown.replace('%', '%%')})"

    def _format_action_invocation(self, action: argparse.Action) -> str:
        hidden = getattr(action, "hidden_aliases", ())
        if hidden:
            action = copy.copy(action)
            action.option_strings = [s for s in action.option_strings if s not in hidden]
        return super()._format_action_invocation(action)


def show_default(value) -> str | None:
    """A default as the user would type it (lists comma-separated); None where there is nothing to show."""
    if value is None or value is False or value == "" or value is argparse.SUPPRESS:
        return None
    if isinstance(value, (list, tuple)):
        return ",".join(str(v) for v in value)
    return str(value)


def renamed(action: argparse.Action, *old: str) -> argparse.Action:
    """Mark ``old`` spellings among ``action``'s option strings (its first one is the name): they still
    work, ``--help`` and error messages do not show them, and using one prints
    ``mesh2tex: warning: OLD is renamed NEW``."""
    missing = [flag for flag in old if flag not in action.option_strings]
    if missing or action.option_strings[0] in old:
        raise ValueError(
            f"{', '.join(missing) or action.option_strings[0]}: not an old spelling of {action.option_strings}"
        )
    action.hidden_aliases = tuple(getattr(action, "hidden_aliases", ())) + old
    action.renamed_from = tuple(getattr(action, "renamed_from", ())) + old
    return action


def add_out(
    parser, help: str, *, required: bool = True, default: str | None = None, alias: str | None = None
) -> argparse.Action:
    """``--out DIR``; ``alias`` (an older spelling such as ``--output``) still works but is not shown."""
    flags = ["--out"] + ([alias] if alias else [])
    action = parser.add_argument(*flags, dest="out", metavar="DIR", required=required, default=default, help=help)
    return renamed(action, alias) if alias else action


def add_overwrite(
    parser,
    help: str = "replace files already in --out (without it, a command that would replace one stops before any work)",
) -> argparse.Action:
    """``--overwrite``: without it a command refuses to replace a file already in ``--out``."""
    return parser.add_argument("--overwrite", action="store_true", help=help)


SHIPPED_MODELS_HELP = "or a shipped model's name (chair, car)"


def add_checkpoint(
    parser,
    help: str,
    *,
    config: "ConfigOptions | None" = None,
    key: str | None = None,
    required: bool = False,
    alias: str | None = None,
) -> argparse.Action:
    """``--checkpoint NAME|PATH``: a generator (a 'train gan' checkpoint, or a shipped model's name,
    which :func:`mesh2tex.models.resolve_checkpoint` turns into its file); ``help`` says what it
    is for. With ``config`` it overrides that config's field ``key``; ``alias``: an old spelling (:func:`renamed`)."""
    flags = ["--checkpoint"] + ([alias] if alias else [])
    kwargs = dict(dest="checkpoint", metavar="NAME|PATH", help=help)
    if config is not None:
        action = config.add(*flags, key=key, **kwargs)
    else:
        action = parser.add_argument(*flags, required=required, **kwargs)
    return renamed(action, alias) if alias else action


MAX_SEEDS = 100_000  # seeds of one command (a range holds at most as many)


def parse_seeds(text: str, flag: str = "--seeds") -> list[int]:
    """Seeds as the user types them: integers and ranges, comma-separated (``0-7``, ``0,2,5-9``; a
    range includes both ends); repeated seeds are kept once, in the order first given. InputError
    (one line naming the text) for anything else."""
    from mesh2tex.errors import InputError

    seeds: list[int] = []
    seen: set[int] = set()
    for part in str(text).split(","):
        part = part.strip()
        if not part:
            continue
        split = part.find("-", 1)  # a range; a leading minus is a negative seed
        try:
            first, last = (int(part), int(part)) if split < 0 else (int(part[:split]), int(part[split + 1 :]))
        except ValueError:
            raise InputError(
                f"{flag} {text!r}: expected integers and ranges, comma-separated, e.g. 0,1,2 or 0-7 or 0,2,5-9"
            ) from None
        if last < first:
            raise InputError(f"{flag} {text!r}: the range {part} runs backwards")
        if last - first >= 100_000:
            raise InputError(f"{flag} {text!r}: the range {part} holds more than 100000 seeds")
        for value in range(first, last + 1):
            if value not in seen:
                seen.add(value)
                seeds.append(value)
        if len(seeds) > MAX_SEEDS:
            raise InputError(f"{flag}: more than {MAX_SEEDS} seeds; run them in parts")
    if not seeds:
        raise InputError(f"{flag}: give at least one seed")
    return seeds


def add_device(parser, help: str = "where to run", default: str | None = "auto") -> argparse.Action:
    """``--device auto|cpu|cuda`` (auto: CUDA when available)."""
    return parser.add_argument("--device", choices=DEVICES, default=default, help=help)


def add_texture_format(parser, config: "ConfigOptions | None" = None, key: str = "texture_format") -> argparse.Action:
    """``--texture-format png|jpeg|webp``: how the baked texture is embedded in the GLBs written
    (:data:`mesh2tex.io.assets.TEXTURE_FORMATS`); with ``config``, it overrides that config's field ``key``."""
    kwargs = dict(
        choices=static_value("mesh2tex.io.assets:TEXTURE_FORMATS"),
        help="image format of the GLB's texture: png (lossless), jpeg or webp (lossy, smaller; "
        "webp needs a viewer with EXT_texture_webp)",
    )
    if config is not None:
        return config.add("--texture-format", key=key, **kwargs)
    return parser.add_argument("--texture-format", default="png", **kwargs)


def add_up(parser) -> argparse.Action:
    """``--up auto|y|z``: the up axis of the user's mesh file (:func:`mesh2tex.geometry.mesh_io.choose_up`)."""
    return parser.add_argument(
        "--up",
        default="auto",
        choices=static_value("mesh2tex.geometry.mesh_io:UP_AXES"),
        help="the mesh file's up axis; auto: y for glTF (by definition), OBJ, PLY and OFF, z for STL (the choice is "
        "printed)",
    )


def add_mesh_output(parser) -> None:
    """The options of a command that hands the user's mesh back textured: ``--up``, ``--uv``, ``--output-mesh``."""
    add_up(parser)
    parser.add_argument(
        "--uv",
        default="auto",
        choices=static_value("mesh2tex.render.bake:UV_MODES"),
        help="the texture's atlas: the mesh's own UVs (keep), a new xatlas atlas (new), or auto: its own when "
        "they are usable (inside [0, 1], charts not overlapping), else new (the reason is printed)",
    )
    parser.add_argument(
        "--output-mesh",
        default="input",
        choices=("input", "prepared"),
        help="input: the user's mesh as given (its vertices, faces, frame and units) with UVs and a baked texture; "
        "prepared: the quad-remeshed, normalised working copy",
    )


# The attribute of the parsed arguments that holds {config: {dest: field key}}: every flag ConfigOptions
# declared, so that config_overrides() passes each of them on and none is forgotten.
CONFIG_FLAGS = "_config_flags"


class ConfigOptions:
    """The options of a command with a config dataclass ``config`` (``"module:Class"``): ``--config YAML``
    (``config_flag``; None: none), ``--print-config`` (unless ``print_config`` is False), and flags that
    each override one field and show its default in ``--help``. The command turns the parsed flags
    into the overrides of its config with :func:`config_overrides`."""

    def __init__(
        self,
        parser,
        config: str,
        *,
        config_flag: str | None = "--config",
        print_config: bool = True,
        what: str = "the config",
    ):
        self.parser, self.config = parser, config
        declared = parser.get_default(CONFIG_FLAGS)
        if declared is None:  # the first config of this parser (an argument group shares its parser's defaults)
            declared = {}
            parser.set_defaults(**{CONFIG_FLAGS: declared})
        self.flags: dict[str, str | tuple[str, ...]] = declared.setdefault(config, {})
        if config_flag:
            parser.add_argument(
                config_flag, metavar="YAML", help=f"YAML file with any fields of {what} (the flags given override it)"
            )
        if print_config and config_flag:
            add_print_config(parser)

    def add(self, *flags, key: str | tuple[str, ...] | None = None, **kwargs) -> argparse.Action:
        """``parser.add_argument(*flags, **kwargs)`` for the field ``key`` (dotted; default: the flag's
        name; a tuple: fields shown comma-separated, as ``--steps MIN,MAX``, whose values the command
        computes from the flag's text and gives :func:`config_overrides`)."""
        action = self.parser.add_argument(*flags, **kwargs)
        action.config_source = (self.config, key or action.dest)
        self.flags[action.dest] = key or action.dest
        return action


def config_overrides(args: argparse.Namespace, config: str | None = None, computed: dict | None = None) -> dict:
    """The overrides of ``config`` ("module:Class"; None: the command's only config) for
    :func:`mesh2tex.config.load_config`: {field key: value} of every flag :meth:`ConfigOptions.add`
    declared for it (None where it was not given, which ``load_config`` skips), then ``computed``
    (values the command derives from its flags: a parsed list, a flag of another config), which
    replace a flag's raw value. A flag with a tuple of fields must have all of them in ``computed``.
    """
    declared = getattr(args, CONFIG_FLAGS, None) or {}
    if config is None:
        if len(declared) != 1:
            raise ValueError(f"name the config: this command declares flags for {sorted(declared) or 'none'}")
        (config,) = declared
    if config not in declared:
        raise ValueError(f"no flags are declared for {config}")
    computed = dict(computed or {})
    overrides = {}
    for dest, key in declared[config].items():
        if isinstance(key, tuple):  # a flag whose text sets several fields: the command parses it
            if any(k not in computed for k in key):
                raise ValueError(f"the flag of {dest!r} sets {', '.join(key)}: give their values in computed")
            continue
        overrides[key] = getattr(args, dest)
    overrides.update(computed)
    return overrides


def add_print_config(parser) -> argparse.Action:
    return parser.add_argument(
        "--print-config",
        action="store_true",
        help="print the resolved config (its defaults, then --config, then the flags given) as YAML and exit",
    )


# ------------------------------------------------------------------------------ static defaults
class NotStatic(ValueError):
    """A default that is not a literal (a computed value): it is not shown."""


def config_default(config: str, key: str | tuple[str, ...]):
    """The default of the dotted field ``key`` of ``config`` ("module:Class"), read from the source;
    None when it is not a literal."""
    if isinstance(key, tuple):
        values = [config_default(config, k) for k in key]
        return None if None in values else values
    node = static_defaults(config)
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return node


@functools.lru_cache(maxsize=None)
def static_defaults(config: str) -> dict:
    """The defaults of the config dataclass ``config`` ("module:Class") as a nested dict, read from its
    source without importing it; fields whose default is not a literal are left out."""
    value = static_value(config)
    if not isinstance(value, dict):
        raise NotStatic(f"{config} is not a class")
    return value


def static_value(target: str):
    """The value of ``target`` ("module:NAME"), a literal module constant or a config class (its defaults)."""
    module, name = target.split(":")
    return _value(*_lookup(module, name))


def _source(module: str) -> Path:
    """The source file of ``module`` (``mesh2tex....``), looked for along the package's ``__path__`` as
    the import system would (a source tree or an installed wheel) without importing any subpackage."""
    import mesh2tex

    package, *parts = module.split(".")
    if package != "mesh2tex" or not parts:
        raise ModuleNotFoundError(f"no module named {module!r} in mesh2tex", name=module)
    for folder in map(Path, mesh2tex.__path__):
        base = folder.joinpath(*parts)
        for candidate in (base / "__init__.py", base.with_suffix(".py")):
            if candidate.is_file():
                return candidate
    raise ModuleNotFoundError(f"no module named {module!r}", name=module)


@functools.lru_cache(maxsize=None)
def _tree(module: str) -> ast.Module:
    path = _source(module)
    return ast.parse(path.read_text(encoding="utf-8"), str(path))


def _lookup(module: str, name: str) -> tuple[str, ast.AST]:
    """(module, node) where ``name`` is defined, following ``from ... import`` re-exports."""
    for node in _tree(module).body:
        if isinstance(node, ast.ClassDef) and node.name == name:
            return module, node
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == name for t in node.targets):
            return module, node.value
        if (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and node.target.id == name
            and node.value
        ):
            return module, node.value
        if isinstance(node, ast.ImportFrom):
            for alias in node.names:
                if (alias.asname or alias.name) == name:
                    return _lookup(_absolute(module, node), alias.name)
    raise NotStatic(f"{module}.{name} not found")


def _absolute(module: str, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    package = module.split(".") if _source(module).name == "__init__.py" else module.split(".")[:-1]
    package = package[: len(package) - (node.level - 1)]
    return ".".join(package + ([node.module] if node.module else []))


def _value(module: str, node: ast.AST):
    if isinstance(node, ast.ClassDef):
        fields = {}
        for stmt in node.body:
            if (
                isinstance(stmt, ast.AnnAssign)
                and isinstance(stmt.target, ast.Name)
                and stmt.value is not None
                and "ClassVar" not in ast.unparse(stmt.annotation)
            ):
                try:
                    fields[stmt.target.id] = _value(module, stmt.value)
                except NotStatic:
                    pass
        return fields
    try:
        return ast.literal_eval(node)
    except (ValueError, TypeError, SyntaxError):
        pass
    if isinstance(node, ast.Name):
        return _value(*_lookup(module, node.id))
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
        keywords = {k.arg: k.value for k in node.keywords}
        if node.func.id == "field" and "default" in keywords:
            return _value(module, keywords["default"])
        if node.func.id == "field" and "default_factory" in keywords:
            factory = keywords["default_factory"]
            if isinstance(factory, ast.Lambda):
                return _value(module, factory.body)
            if isinstance(factory, ast.Name) and factory.id in ("list", "dict"):
                return [] if factory.id == "list" else {}
            return _value(module, factory)
        if node.func.id in ("list", "tuple") and len(node.args) == 1 and not node.keywords:
            return (list if node.func.id == "list" else tuple)(_value(module, node.args[0]))
        # Config(field=value, ...): the class's defaults, those fields changed
        if not node.args and None not in keywords:
            found = _lookup(module, node.func.id)
            if isinstance(found[1], ast.ClassDef):
                return {**_value(*found), **{name: _value(module, value) for name, value in keywords.items()}}
    raise NotStatic(ast.unparse(node))

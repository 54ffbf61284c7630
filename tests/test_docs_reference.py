"""The reference pages (docs/reference/cli.md, config.md) are what docs/gen_reference.py makes from the
parsers and config dataclasses: a flag or config field added without regenerating them fails here."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _generator():
    spec = importlib.util.spec_from_file_location("gen_reference", ROOT / "docs" / "gen_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_committed_reference_is_what_the_code_generates():
    gen = _generator()
    for name, make in gen.PAGES.items():
        committed = (ROOT / "docs" / "reference" / name).read_text(encoding="utf-8")
        assert committed == make().rstrip("\n") + "\n", (
            f"docs/reference/{name} differs from what the code gives: run `make reference` and commit it"
        )


def test_reference_lists_every_command_and_config():
    gen = _generator()
    from mesh2tex.cli import COMMANDS

    cli = gen.cli_page()
    for command, sub in COMMANDS:
        assert f"## mesh2tex {command}{' ' + sub if sub else ''}\n" in cli
    config = gen.config_page()
    for _, cls, _ in gen._config_classes():
        assert f"## {cls.__name__}\n" in config

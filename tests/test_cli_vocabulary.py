"""One vocabulary for every command: the same flag for the same thing, checked by walking every
subcommand's parser (``mesh2tex.cli.COMMANDS``).

* every command writes into ``--out DIR`` and takes ``--overwrite`` (without it, files already there are kept);
* every command that reads a generator takes it as ``--checkpoint NAME|PATH`` (a file, or a shipped model's name);
* every command with a config takes ``--config YAML`` and ``--print-config``;
* every command that computes takes ``--device auto|cpu|cuda``;
* seeds are ``--seed N`` (one) or ``--seeds`` (integers and ranges: ``0-7``, ``0,2,5-9``);
* an old spelling still works, hidden from ``--help``, and says ``mesh2tex: warning: OLD is renamed NEW``;
* a warning is one line, ``mesh2tex: warning: ...``.

``EXCEPTIONS`` lists what a command does not follow yet: (command, flag) -> why.
"""

from __future__ import annotations

import argparse
import ast
import warnings
from pathlib import Path

import pytest

import mesh2tex
from mesh2tex.cli import COMMANDS, build_parser, main, show_warning
from mesh2tex.errors import InputError
from mesh2tex.options import HelpFormatter, parse_seeds

ROOT = Path(__file__).resolve().parents[1]
ARGVS = [(command,) + ((sub,) if sub else ()) for command, sub in COMMANDS]
# Commands without a config dataclass: a handful of flags each, recorded in the index.json they write.
CONFIG_LESS = {("prepare", "shapes"), ("prepare", "images"), ("prepare", "synthetic")}
# Commands that only prepare data, on the CPU (QuadriFlow, GrabCut, the world's small renders).
DEVICE_LESS = {("prepare", "shapes"), ("prepare", "images"), ("prepare", "synthetic")}
# Commands that read a generator (a 'train gan' checkpoint or a shipped model).
GENERATOR_READERS = {("train", "pose"), ("train", "noc"), ("infer", "generate"), ("infer", "transfer"), ("evaluate",)}
# Spellings of a shared flag that no command shows (an old one may stay as a hidden alias).
OTHER_SPELLINGS = {
    "--output",
    "--output-dir",
    "--outdir",
    "--gan",
    "--generator",
    "--gan-checkpoint",
    "--ckpt",
    "--model",
    "--protocol-config",
    "--config-file",
    "--force",
    "--replace",
    "--random-seed",
    "--rng-seed",
    "--cpu",
    "--gpu",
    "--cuda",
}
EXCEPTIONS: dict[tuple[tuple[str, ...], str], str] = {}


def leaf_parser(argv) -> argparse.ArgumentParser:
    parser = build_parser(list(argv))
    for word in argv:
        parser = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[word]
    return parser


def actions(argv) -> dict[str, argparse.Action]:
    return {s: a for a in leaf_parser(argv)._actions for s in a.option_strings}


def shown(action: argparse.Action) -> list[str]:
    """The option strings ``--help`` shows."""
    return [s for s in action.option_strings if s not in getattr(action, "hidden_aliases", ())]


def has(argv, flag) -> bool:
    if (argv, flag) in EXCEPTIONS:
        pytest.xfail(EXCEPTIONS[(argv, flag)])
    return flag in actions(argv)


def stage_defines(argv, function: str) -> bool:
    """Whether the command's stage module defines ``function`` (read from its source, without importing it)."""
    module = COMMANDS[(argv[0], argv[1] if len(argv) > 1 else None)][0]
    parts = module.split(".")[1:]
    for base in map(Path, mesh2tex.__path__):
        path = base.joinpath(*parts).with_suffix(".py")
        if path.is_file():
            tree = ast.parse(path.read_text(encoding="utf-8"))
            return any(isinstance(node, ast.FunctionDef) and node.name == function for node in tree.body)
    raise AssertionError(f"no source for {module}")


def test_the_walk_covers_every_subcommand_and_the_exceptions_are_real():
    assert len(ARGVS) == len(COMMANDS) >= 12
    for argv, flag in EXCEPTIONS:
        assert argv in ARGVS and flag not in actions(argv), (
            f"{' '.join(argv)} {flag} is no longer an exception: remove it"
        )


@pytest.mark.parametrize("argv", ARGVS, ids=" ".join)
def test_every_command_writes_into_out_and_refuses_to_replace_without_overwrite(argv):
    assert has(argv, "--out") and has(argv, "--overwrite")
    found = actions(argv)
    assert found["--out"].dest == "out" and found["--out"].metavar == "DIR" and shown(found["--out"]) == ["--out"]
    overwrite = found["--overwrite"]
    assert (
        isinstance(overwrite, argparse._StoreTrueAction)
        and overwrite.dest == "overwrite"
        and shown(overwrite) == ["--overwrite"]
    )


@pytest.mark.parametrize("argv", ARGVS, ids=" ".join)
def test_a_generator_is_read_by_checkpoint_name_or_path(argv):
    found = actions(argv)
    if argv not in GENERATOR_READERS:
        return
    assert has(argv, "--checkpoint")
    checkpoint = found["--checkpoint"]
    assert checkpoint.dest == "checkpoint" and shown(checkpoint) == ["--checkpoint"]
    assert "shipped model" in checkpoint.help and "(chair, car)" in checkpoint.help, checkpoint.help


@pytest.mark.parametrize("argv", ARGVS, ids=" ".join)
def test_no_command_shows_another_spelling_of_a_shared_flag(argv):
    visible = {s for a in leaf_parser(argv)._actions for s in shown(a)}
    assert not visible & OTHER_SPELLINGS, sorted(visible & OTHER_SPELLINGS)
    assert not {s for s in visible if "seed" in s} - {"--seed", "--seeds"}


@pytest.mark.parametrize("argv", ARGVS, ids=" ".join)
def test_every_command_with_a_config_reads_and_prints_it(argv):
    assert stage_defines(argv, "build_config") == (argv not in CONFIG_LESS) or (argv, "--config") in EXCEPTIONS, (
        "a command has a config exactly when its stage builds one"
    )
    if argv in CONFIG_LESS:
        assert "--config" not in actions(argv) and "--print-config" not in actions(argv)
        return
    assert has(argv, "--config") and has(argv, "--print-config")
    found = actions(argv)
    assert (
        found["--config"].metavar == "YAML"
        and found["--config"].dest == "config"
        and shown(found["--config"]) == ["--config"]
    )
    assert isinstance(found["--print-config"], argparse._StoreTrueAction)


@pytest.mark.parametrize("argv", ARGVS, ids=" ".join)
def test_every_computing_command_takes_the_device_alike(argv):
    if argv in DEVICE_LESS:
        assert "--device" not in actions(argv)
        return
    assert has(argv, "--device")
    assert tuple(actions(argv)["--device"].choices) == ("auto", "cpu", "cuda")


@pytest.mark.parametrize("argv", ARGVS, ids=" ".join)
def test_seeds_are_spelled_and_read_alike(argv, tmp_path, monkeypatch, capsys):
    found = actions(argv)
    if "--seed" in found:
        assert found["--seed"].type is int and found["--seed"].dest == "seed"
    if "--seeds" in found:  # a list: read by mesh2tex.options.parse_seeds
        monkeypatch.chdir(tmp_path)
        required = [w for a in leaf_parser(argv)._actions if a.required for w in (a.option_strings[0], "x")]
        assert main([*argv, *required, "--seeds", "0-2,7", "--print-config"]) == 0, capsys.readouterr().err
        assert "- 7" in capsys.readouterr().out


@pytest.mark.parametrize(
    "text, seeds",
    [
        ("3", [3]),
        ("0,1,2", [0, 1, 2]),
        ("0-7", list(range(8))),
        ("0,2,5-9", [0, 2, 5, 6, 7, 8, 9]),
        (" 4 , 1-2 ,", [4, 1, 2]),
        ("1,1,0-2", [1, 0, 2]),
    ],
)
def test_seeds_take_lists_and_ranges(text, seeds):
    assert parse_seeds(text) == seeds


@pytest.mark.parametrize(
    "text, says",
    [
        ("a", "expected integers and ranges"),
        ("5-2", "runs backwards"),
        ("", "at least one seed"),
        ("0-9999999", "more than 100000"),
        ("1-2-3", "expected integers"),
    ],
)
def test_bad_seeds_are_one_line_naming_the_text(text, says):
    with pytest.raises(InputError, match=says):
        parse_seeds(text)


# ------------------------------------------------------------------------------------ old spellings
RENAMED = [
    (("train", "pose"), "--gan", "--checkpoint", ["--shapes", "s", "--out", "o"]),
    (("train", "noc"), "--gan", "--checkpoint", ["--shapes", "s", "--out", "o"]),
    (("evaluate",), "--gan", "--checkpoint", ["--out", "o"]),
    (("evaluate",), "--protocol-config", "--config", ["--out", "o"]),
    (("prepare", "images"), "--output", "--out", ["--input", "i"]),
]


@pytest.mark.parametrize("argv, old, new, rest", RENAMED, ids=lambda v: v if isinstance(v, str) else " ".join(v))
def test_an_old_spelling_still_works_hidden_and_says_its_new_name(argv, old, new, rest, capsys):
    parser = build_parser(list(argv))
    assert getattr(parser.parse_args([*argv, *rest, old, "v"]), actions(argv)[new].dest) == "v"
    assert capsys.readouterr().err == f"mesh2tex: warning: {old} is renamed {new}\n"
    parser.parse_args([*argv, *rest, new, "v"])
    assert capsys.readouterr().err == "", "the new spelling says nothing"
    help_text = leaf_parser(argv).format_help()
    assert f"{old} " not in help_text and f"{old}," not in help_text and new in help_text


def test_every_old_spelling_is_marked_renamed():
    """A hidden alias without the warning would keep an old spelling alive unnoticed."""
    for argv in ARGVS:
        for action in leaf_parser(argv)._actions:
            assert set(getattr(action, "hidden_aliases", ())) == set(getattr(action, "renamed_from", ())), (
                argv,
                action.option_strings,
            )
            assert all(flag in {old for _, old, _, _ in RENAMED} for flag in getattr(action, "renamed_from", ())), (
                argv,
                action.option_strings,
            )


# ----------------------------------------------------------------------------------------- warnings
def test_a_library_warning_is_one_line_without_its_source(capsys):
    import mesh2tex.nn.vgg as vgg

    text = (
        "no ImageNet VGG19 weights found (looked for X); using a random-weight VGG19.\nStyle losses still match colour."
    )
    show_warning(UserWarning(text), UserWarning, vgg.__file__, 204)
    err = capsys.readouterr().err
    assert (
        err == "mesh2tex: warning: no ImageNet VGG19 weights found (looked for X); using a random-weight VGG19. Style "
        "losses still match colour.\n"
    )
    show_warning(
        UserWarning("sparse CSR support is in beta"),
        UserWarning,
        "/x/lib/python3/site-packages/torch/sparse/__init__.py",
        9,
    )
    assert capsys.readouterr().err == "mesh2tex: warning: sparse CSR support is in beta (UserWarning from torch)\n"


def test_warnings_raised_while_a_command_runs_are_one_line(monkeypatch, capsys):
    import mesh2tex.infer.generate

    import mesh2tex.nn.vgg as vgg

    def run(args):  # a warning raised in the library, as the VGG fallback is
        warnings.warn_explicit(
            "random-weight VGG19", UserWarning, vgg.__file__, 204, module="mesh2tex.nn.vgg", registry={}
        )
        return 0

    monkeypatch.setattr(mesh2tex.infer.generate, "run", run)
    assert main(["infer", "generate", "--checkpoint", "c", "--mesh", "m", "--out", "o"]) == 0
    err = capsys.readouterr().err
    assert err == "mesh2tex: warning: random-weight VGG19\n", err
    assert warnings.showwarning is not show_warning, "the command's formatter does not outlive it"


# -------------------------------------------------------------------------------- progress and time
def test_evaluate_shows_progress(tmp_path, monkeypatch, capsys):
    import numpy as np
    from PIL import Image

    for folder in ("renders", "images"):
        (tmp_path / folder).mkdir()
        for k in range(2):
            Image.fromarray(np.full((16, 16, 3), 40 * k + (folder == "images") * 10, np.uint8)).save(
                tmp_path / folder / f"v{k}.png"
            )
    monkeypatch.setenv("MESH2TEX_PROGRESS", "1")
    assert (
        main(
            [
                "evaluate",
                "--pairs",
                "--renders",
                str(tmp_path / "renders"),
                "--images",
                str(tmp_path / "images"),
                "--out",
                str(tmp_path / "out"),
            ]
        )
        == 0
    )
    assert "evaluate: 100%" in capsys.readouterr().err


def test_a_long_default_says_how_long():
    help_text = HelpFormatter("mesh2tex")._get_help_string(actions(("train", "gan"))["--iters"])
    assert "20000 take about 2.5 h on a 2-core CPU" in help_text and help_text.endswith("(default: 20000)"), help_text


def test_evaluate_reads_the_config_of_the_mode_asked_for(tmp_path, capsys):
    import yaml

    (tmp_path / "sets.yaml").write_text("kid_subsets: 7\n")
    (tmp_path / "generation.yaml").write_text("latents: 5\n")
    assert main(["evaluate", "--config", str(tmp_path / "sets.yaml"), "--print-config"]) == 0
    assert yaml.safe_load(capsys.readouterr().out)["kid_subsets"] == 7
    assert (
        main(
            [
                "evaluate",
                "--generation",
                "--config",
                str(tmp_path / "generation.yaml"),
                "--repeats",
                "3",
                "--print-config",
            ]
        )
        == 0
    )
    printed = yaml.safe_load(capsys.readouterr().out)
    assert (printed["latents"], printed["repeats"]) == (5, 3)

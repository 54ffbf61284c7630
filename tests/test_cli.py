"""The command line as a user meets it: ``--help`` is fast (no torch import) and shows every default,
``--print-config`` prints the resolved config and does nothing else, every command takes ``--out``
and ``--device`` the same way, and a bad option is one ``mesh2tex: error:`` line with exit status 2."""

from __future__ import annotations

import argparse
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from mesh2tex.cli import COMMANDS, build_parser, main
from mesh2tex.config import config_to_dict
from mesh2tex.errors import InputError, UserError
from mesh2tex.options import HelpFormatter, show_default, static_defaults

ROOT = Path(__file__).resolve().parents[1]
ARGVS = [[command] + ([sub] if sub else []) for command, sub in COMMANDS]
CONFIG_COMMANDS = {  # argv -> the config class --print-config prints
    ("train", "gan"): "mesh2tex.train.gan_config:TrainGanConfig",
    ("train", "pose"): "mesh2tex.nn.view_nets:ViewTrainConfig",
    ("train", "noc"): "mesh2tex.nn.view_nets:ViewTrainConfig",
    ("train", "nca"): "mesh2tex.train.nca:TrainNCAConfig",
    ("infer", "generate"): "mesh2tex.infer.generate:GenerateConfig",
    ("infer", "transfer"): "mesh2tex.transfer.config:TransferConfig",
    ("evaluate",): "mesh2tex.metrics.evaluate:EvaluateConfig",
    ("evaluate", "--protocols"): "mesh2tex.evaluation.protocol_config:ProtocolConfig",
    ("evaluate", "--generation"): "mesh2tex.evaluation.generation:GenerationConfig",
    ("demo",): "mesh2tex.infer.demo:DemoConfig",
}
DEVICE_COMMANDS = [argv for argv in ARGVS if argv[0] != "prepare"]  # preparation runs on the CPU


def run_cli(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MESH2TEX_PROGRESS": "0"}
    return subprocess.run([sys.executable, *args], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)


def config_class(target: str):
    module, name = target.split(":")
    return getattr(importlib.import_module(module), name)


def leaf_parser(argv: list[str]) -> argparse.ArgumentParser:
    """The parser of the command ``argv`` names."""
    parser = build_parser(argv)
    for word in argv:
        parser = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[word]
    return parser


# ------------------------------------------------------------------------------------------ --help
def test_help_does_not_import_torch():
    result = run_cli("-X", "importtime", "-m", "mesh2tex", "train", "gan", "--help")
    assert result.returncode == 0, result.stderr[-2000:]
    assert "--iters" in result.stdout
    imported = [
        line.rsplit("|", 1)[-1].strip() for line in result.stderr.splitlines() if line.startswith("import time:")
    ]
    assert "mesh2tex.options" in imported  # the import log is there
    assert not [m for m in imported if m.split(".")[0] in ("torch", "numpy")], "--help imported torch or numpy"


def test_every_help_exits_0_without_torch():
    argvs = [[]] + [[c] for c in sorted({c for c, _ in COMMANDS})] + ARGVS
    script = (
        f"import json, sys\nfrom mesh2tex.cli import main\ncodes = []\nfor argv in {argvs!r}:\n"
        "    try:\n        main(argv + ['--help'])\n    except SystemExit as e:\n        codes.append(e.code)\n"
        "print(json.dumps({'codes': codes, 'torch': 'torch' in sys.modules}), file=sys.stderr)"
    )
    result = run_cli("-c", script)
    report = json.loads(result.stderr.strip().splitlines()[-1])
    assert report == {"codes": [0] * len(argvs), "torch": False}, result.stderr[-2000:]


@pytest.mark.parametrize("argv", ARGVS, ids=" ".join)
def test_help_shows_every_default(argv):
    """Every option with a default shows it, config flags the config's own default (as the imported class has it)."""
    formatter = HelpFormatter(prog="mesh2tex")
    for action in leaf_parser(argv)._actions:
        if not action.option_strings or action.help is argparse.SUPPRESS or isinstance(action, argparse._HelpAction):
            continue
        source = getattr(action, "config_source", None)
        if source is not None:
            defaults = config_to_dict(config_class(source[0])())
            keys = source[1] if isinstance(source[1], tuple) else (source[1],)
            values = []
            for key in keys:
                node = defaults
                for part in key.split("."):
                    node = node[part]
                values.append(node)
            expected = show_default(values if len(values) > 1 else values[0])
        else:
            expected = show_default(action.default)
        text = formatter._get_help_string(action)
        if expected is not None and "default" not in (action.help or ""):
            assert text.endswith(f"(default: {expected})"), (action.option_strings, text)


@pytest.mark.parametrize("target", sorted(set(CONFIG_COMMANDS.values())))
def test_static_defaults_are_the_classes_defaults(target):
    """--help reads the defaults from the source (no torch import): they must be what the class gives."""
    assert static_defaults(target) == config_to_dict(config_class(target)())


# ---------------------------------------------------------------------------------- --print-config
@pytest.mark.parametrize("argv", sorted(CONFIG_COMMANDS), ids=" ".join)
def test_print_config_prints_the_defaults_and_does_nothing_else(argv, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main([*argv, "--print-config"]) == 0
    printed = yaml.safe_load(capsys.readouterr().out)
    assert printed == yaml.safe_load(yaml.safe_dump(config_to_dict(config_class(CONFIG_COMMANDS[argv])())))
    assert list(tmp_path.iterdir()) == []


def test_print_config_merges_the_config_file_and_the_flags(tmp_path, capsys):
    (tmp_path / "c.yaml").write_text("batch: 3\niters: 100\ngenerator: {z_dim: 16}\n")
    assert main(["train", "gan", "--config", str(tmp_path / "c.yaml"), "--iters", "7", "--print-config"]) == 0
    printed = yaml.safe_load(capsys.readouterr().out)
    assert (printed["iters"], printed["batch"], printed["generator"]["z_dim"]) == (7, 3, 16)
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yaml").write_text("iters: 5\n")
    assert main(["train", "gan", "--out", str(run), "--resume", "--print-config"]) == 0  # the run's own config
    assert yaml.safe_load(capsys.readouterr().out)["iters"] == 5
    assert main(["demo", "--quick", "--seed", "4", "--print-config"]) == 0
    printed = yaml.safe_load(capsys.readouterr().out)
    assert (printed["gan"]["iters"], printed["gan"]["channels"], printed["seed"]) == (2, [8, 8, 8], 4)


def test_print_config_reports_a_bad_value_as_one_line(tmp_path, capsys):
    assert main(["train", "nca", "--steps", "9,3", "--print-config"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("mesh2tex: error: --steps 9,3")


# ---------------------------------------------------------------------------- one command style
@pytest.mark.parametrize("argv", ARGVS, ids=" ".join)
def test_every_command_takes_out_and_device_alike(argv):
    actions = {s: a for a in leaf_parser(argv)._actions for s in a.option_strings}
    assert actions["--out"].dest == "out"
    if argv in DEVICE_COMMANDS:
        assert tuple(actions["--device"].choices) == ("auto", "cpu", "cuda")
    else:
        assert "--device" not in actions


# every command that writes a textured GLB
GLB_COMMANDS = [
    ["infer", "generate"],
    ["infer", "transfer"],
    ["infer", "nca"],
    ["demo"],
]


@pytest.mark.parametrize("argv", GLB_COMMANDS, ids=" ".join)
def test_every_command_writing_a_glb_takes_the_texture_format_alike(argv):
    from mesh2tex.io.assets import TEXTURE_FORMATS

    action = next(a for a in leaf_parser(argv)._actions if "--texture-format" in a.option_strings)
    assert tuple(action.choices) == TEXTURE_FORMATS
    assert HelpFormatter("mesh2tex")._get_help_string(action).endswith("(default: png)")


def test_a_texture_format_from_a_config_file_is_checked(tmp_path, capsys):
    (tmp_path / "c.yaml").write_text("texture_format: gif\n")
    (tmp_path / "demo.yaml").write_text("transfer: {texture_format: gif}\n")
    for argv, config in (
        (["infer", "generate", "--checkpoint", "c", "--mesh", "m", "--out", "o"], "c.yaml"),
        (["demo"], "demo.yaml"),
    ):
        assert main([*argv, "--config", str(tmp_path / config), "--print-config"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "texture_format 'gif': choose one of png, jpeg, webp" in err, err
    assert main(["demo", "--texture-format", "webp", "--print-config"]) == 0
    assert yaml.safe_load(capsys.readouterr().out)["transfer"]["texture_format"] == "webp"


@pytest.mark.parametrize("argv", DEVICE_COMMANDS, ids=" ".join)
def test_a_bad_device_is_one_line_and_exit_2(argv, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, "--out", "o", "--device", "gpu"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("mesh2tex: error: argument --device: invalid choice: 'gpu'"), err


@pytest.mark.parametrize(
    "argv, says",
    [
        (["train", "gan", "--out", "o"], "required: --shapes, --images; see 'mesh2tex train gan --help'"),
        (
            ["train", "gan", "--shapes", "s", "--images", "i", "--out", "o", "--bogus", "1"],
            "unrecognized arguments: --bogus 1; see 'mesh2tex train gan --help'",
        ),
        (["prepare", "shapes", "--input", "x"], "required: --out; see"),  # not '--out/--output': the alias stays hidden
        (
            ["train", "gan", "--shapes", "s", "--images", "i", "--out", "o", "--iters", "many"],
            "argument --iters: invalid int value: 'many'",
        ),
    ],
)
def test_a_bad_option_is_one_line_naming_the_commands_help(argv, says, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("mesh2tex: error: ") and says in err, err


@pytest.mark.parametrize("sub", ["shapes", "images", "synthetic"])
def test_prepare_keeps_output_as_a_hidden_alias_of_out(sub, capsys):
    argv = ["prepare", sub] + ([] if sub == "synthetic" else ["--input", "x"])
    assert build_parser(argv).parse_args(argv + ["--output", "old"]).out == "old"
    assert build_parser(argv).parse_args(argv + ["--out", "new"]).out == "new"
    with pytest.raises(SystemExit):
        main(["prepare", sub, "--help"])
    assert "--output" not in capsys.readouterr().out


def test_backgrounds_named_in_the_options_are_the_commands():
    from mesh2tex.evaluate.evaluate import BACKGROUNDS
    from mesh2tex.evaluate.options import BACKGROUNDS as NAMES

    assert sorted(BACKGROUNDS) == sorted(NAMES)


def test_demo_refuses_a_missing_gpu_before_any_stage(tmp_path, capsys):
    import torch

    if torch.cuda.is_available():
        pytest.skip("a GPU is there")
    assert main(["demo", "--quick", "--device", "cuda", "--out", str(tmp_path / "demo")]) == 2
    assert "no CUDA device" in capsys.readouterr().err and not (tmp_path / "demo").exists()


# --------------------------------------------------------------------------- config flags
def flag_value(action: argparse.Action, default):
    """(text for the command line, the field's value it must give) of a config flag: anything but the default."""
    from mesh2tex.evaluation.report import BASELINES, PROTOCOLS
    from mesh2tex.models import resolve_checkpoint
    from mesh2tex.transfer import ABLATIONS

    lists = {"--only": PROTOCOLS, "--ablations": ABLATIONS, "--baselines": BASELINES}  # comma-separated names
    flag = action.option_strings[0]
    if flag in lists:
        name = list(lists[flag])[-1]
        return name, [name]
    if flag == "--seeds":
        return "3,4", [3, 4]
    if flag == "--steps":
        return "3,5", [3, 5]
    if flag == "--checkpoint":  # a generator that must exist: a shipped model's name, resolved to its file
        return "chair", str(resolve_checkpoint("chair", "gan"))
    if action.choices:
        choice = next(c for c in action.choices if c != default)
        return choice, choice
    if action.type is int:
        value = default * 2 if default else 3  # doubled: a power of two stays one
        return str(value), value
    if action.type is float:
        value = default / 2 if default else 0.5
        return str(value), value
    return "elsewhere", "elsewhere"


def field(config: dict, key: str | tuple[str, ...]):
    if isinstance(key, tuple):
        return [field(config, k) for k in key]
    for part in key.split("."):
        config = config[part]
    return config


@pytest.mark.parametrize("argv", sorted(CONFIG_COMMANDS), ids=" ".join)
def test_every_config_flag_reaches_its_field(argv, tmp_path, monkeypatch, capsys):
    """A flag declared for a config field and left out of the command's overrides would be silently
    ignored (it once was: --texture-size of infer transfer): set each to another value, print the config."""
    monkeypatch.chdir(tmp_path)
    target = CONFIG_COMMANDS[argv]
    defaults = config_to_dict(config_class(target)())
    flags = [
        a
        for a in leaf_parser([w for w in argv if not w.startswith("-")])._actions
        if getattr(a, "config_source", (None,))[0] == target
    ]
    assert flags, f"{target} declares no flags"
    for action in flags:
        key = action.config_source[1]
        text, expected = flag_value(action, field(defaults, key))
        assert main([*argv, action.option_strings[0], text, "--print-config"]) == 0, capsys.readouterr().err
        printed = yaml.safe_load(capsys.readouterr().out)
        assert field(printed, key) == expected, (action.option_strings[0], key)
        assert field(printed, key) != field(defaults, key) or isinstance(key, tuple)


# ----------------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    "error, code", [(InputError("m.obj: the mesh has no faces"), 2), (UserError("--pool 0: too small", exit_code=4), 4)]
)
def test_input_and_user_errors_are_one_line(error, code, monkeypatch, capsys):
    """The library's InputError (a ValueError) and a command's UserError end as one line and their exit status."""
    import mesh2tex.infer.generate

    def run(args):
        raise error

    monkeypatch.setattr(mesh2tex.infer.generate, "run", run)
    assert main(["infer", "generate", "--checkpoint", "c", "--mesh", "m", "--out", "o"]) == code
    assert capsys.readouterr().err == f"mesh2tex: error: {error}\n"
    assert issubclass(InputError, ValueError)


def test_any_other_value_error_is_a_bug_with_its_traceback(monkeypatch):
    import mesh2tex.infer.generate

    def run(args):
        raise ValueError("an index three calls deep")

    monkeypatch.setattr(mesh2tex.infer.generate, "run", run)
    with pytest.raises(ValueError, match="three calls deep"):
        main(["infer", "generate", "--checkpoint", "c", "--mesh", "m", "--out", "o"])

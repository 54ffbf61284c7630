"""A property of the whole command line: for every subcommand (``mesh2tex.cli.COMMANDS``) and every
option that takes a value, a bad value ends with exit status 2 and one ``mesh2tex: error:`` line of
at most 1 kB, never a traceback, and nothing is left in ``--out``.

The values are a table of the kinds users and scripts get wrong (not a number, NaN, infinities,
beyond 64 bits, empty, a whole paragraph, control characters). The inputs a command requires are
paths that do not exist, so no value can start real work; the two commands that need no input
(``prepare synthetic``, ``demo``) would, and a value they accepted fails the test before any work.
"""

from __future__ import annotations

import argparse

import pytest

from mesh2tex.cli import COMMANDS, build_parser, main

BAD_VALUES = [
    "not-a-number",
    "nan",
    "inf",
    "-inf",
    "1e400",
    "99999999999999999999",
    "-99999999999999999999",
    "",
    "x" * 3000,
    "1,2,,3",
    "\x1b[2J\x00",
    "0x10",
]
ARGVS = [(command,) + ((sub,) if sub else ()) for command, sub in COMMANDS]
# options a bad value of which is not an error: free text
FREE_TEXT = {"--out", "--output", "--name", "--tag"}
# values these options accept on purpose (a seed list's empty parts are skipped)
ACCEPTED = {("--seeds", "1,2,,3"), ("--seeds", "0x10")}


def leaf(argv) -> argparse.ArgumentParser:
    parser = build_parser(list(argv))
    for word in argv:
        parser = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[word]
    return parser


def valued_options(argv) -> list[argparse.Action]:
    return [
        a
        for a in leaf(argv)._actions
        if a.option_strings
        and a.nargs != 0
        and not isinstance(a, argparse._HelpAction)
        and a.option_strings[0] not in FREE_TEXT
        and a.dest not in ("print_config",)
    ]


def base_argv(argv, tmp_path, skip: str) -> list[str]:
    """``argv`` with every required option given a missing path (except ``skip``) and ``--out``."""
    words = list(argv) + ["--out", str(tmp_path / "out")]
    for action in leaf(argv)._actions:
        if action.required and action.option_strings and action.option_strings[0] not in ("--out", skip):
            words += [action.option_strings[0]] + [str(tmp_path / "missing")] * (
                action.nargs if isinstance(action.nargs, int) else 1
            )
    return words


CASES = [(argv, action.option_strings[0]) for argv in ARGVS for action in valued_options(argv)]


def test_the_table_covers_every_subcommand():
    assert {argv for argv, _ in CASES} == set(ARGVS)
    assert len(CASES) >= 100


@pytest.fixture(autouse=True)
def no_real_work(monkeypatch):
    """A value accepted by a command that needs no input would start real work: fail there instead."""
    import mesh2tex.data_prep.synthetic as synthetic
    import mesh2tex.infer.demo as demo

    def accepted(*args, **kwargs):
        raise AssertionError("a bad value was accepted and the work began")

    monkeypatch.setattr(synthetic, "plan", accepted)
    monkeypatch.setattr(demo, "run_pipeline", accepted)
    monkeypatch.setenv("MESH2TEX_PROGRESS", "0")


@pytest.mark.parametrize("argv, flag", CASES, ids=[f"{' '.join(a)} {f}" for a, f in CASES])
def test_every_bad_value_of_every_option_is_one_line(argv, flag, tmp_path, capsys):
    action = next(a for a in leaf(argv)._actions if flag in a.option_strings)
    count = action.nargs if isinstance(action.nargs, int) else 1
    for value in BAD_VALUES:
        if (flag, value) in ACCEPTED:
            continue
        words = base_argv(argv, tmp_path, flag) + [flag] + [value] * count
        capsys.readouterr()
        try:
            code = main(words)
        except SystemExit as stop:  # the option parser's refusal (mesh2tex.options.Parser.error)
            code = stop.code
        err = capsys.readouterr().err
        errors = [line for line in err.splitlines() if line.startswith("mesh2tex: error:")]
        assert code == 2, f"{' '.join(argv)} {flag} {value[:40]!r}: exit {code}\n{err[-2000:]}"
        assert "Traceback" not in err and len(errors) == 1, f"{flag} {value[:40]!r}: {err[-2000:]}"
        assert len(errors[0].encode()) <= 1024, f"{flag} {value[:40]!r}: a {len(errors[0])}-character line"
        assert not (tmp_path / "out").exists(), f"{flag} {value[:40]!r}: --out was created"


@pytest.mark.parametrize(
    "expression",
    [
        "10**400",
        "9" * 400,
        "2.0**2.0**2.0**2.0**2.0**2.0",
        "1/0",
        "x/0",
        "(-8)**0.5",
        "exp(1000)",
        "x" + "+x" * 2000,
        "-(" * 300 + "x" + ")" * 300,
        "-" * 999 + "x",
        "x >",
        "__import__('os')",
    ],
)
def test_a_bad_mask_expression_is_one_line(expression):
    """``infer nca --graft-mask/--regrow`` expressions: an arithmetic overflow, a division by zero, a
    root of a negative number, a paragraph, deep nesting: one InputError line under 1 kB, no traceback."""
    import numpy as np

    from mesh2tex.errors import InputError
    from mesh2tex.geometry.regions import expression_weights

    with pytest.raises(InputError) as caught:
        expression_weights(expression, np.random.default_rng(0).uniform(-1, 1, (50, 3)))
    message = str(caught.value)
    assert message.startswith("graft mask ") and "\n" not in message and len(message.encode()) < 1000, message


@pytest.mark.parametrize("angle", ["1e308", "-1e308", "361"])
def test_an_angle_beyond_a_turn_names_angle(angle, tmp_path, capsys):
    """``infer nca --angle``: a finite angle far beyond a turn is refused naming --angle, before any
    file is read (it once ran and ended in non-finite states blamed on --steps)."""
    words = base_argv(("infer", "nca"), tmp_path, "--angle") + [f"--angle={angle}"]
    assert main(words) == 2
    err = capsys.readouterr().err
    assert (
        err.count("\n") == 1
        and f"--angle {float(angle)!r}: must be in [-360, 360] degrees" in err
        and "--steps" not in err
    ), err
    assert not (tmp_path / "out").exists()

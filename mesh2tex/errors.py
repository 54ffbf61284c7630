"""The two errors a user sees as a single line (and a non-zero exit) instead of a traceback.

The library raises :class:`InputError`, a ``ValueError``, so that a program calling it catches bad
input as it catches any other bad value; the commands (``data_prep``, ``train``, ``infer``) raise
:class:`UserError` for a bad option or combination of options. ``mesh2tex/cli.py`` prints either as
``mesh2tex: error: <message>``. The one-line messages that are not errors live here too: a warning
(:func:`warning`, something the user should act on) and a note (:func:`note`, a choice made for them).
"""

import sys


class InputError(ValueError):
    """Bad input data or a bad request: the message names the file or the option and what is wrong.

    The command line prints it as one line and exits with status 2; any other ValueError that
    escapes is a bug and keeps its traceback.
    """


class UserError(Exception):
    """A command's refusal of what it was asked (an option, a combination of options, a run folder):
    the message names the option or the file and what is wrong.

    The command-line entry point prints ``mesh2tex: error: <message>`` and exits with ``exit_code``.
    Anything else that escapes is a bug and keeps its traceback.
    """

    def __init__(self, message: str, exit_code: int = 2):
        super().__init__(message)
        self.exit_code = exit_code


# The most an error message holds (the line under 1 kB with its prefix): a value quoted in it (a paragraph passed as a
# number) is cut to fit.
MAX_MESSAGE_CHARS = 900


def one_line(message) -> str:
    """``message`` as one line of at most :data:`MAX_MESSAGE_CHARS` characters (what ``mesh2tex: error:`` prints)."""
    text = " ".join(part.strip() for part in str(message).splitlines() if part.strip())
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)  # no terminal control characters
    return text if len(text) <= MAX_MESSAGE_CHARS else text[: MAX_MESSAGE_CHARS - 30] + f" ... ({len(text)} characters)"


def _line(prefix: str, message) -> None:
    text = " ".join(line.strip() for line in str(message).splitlines() if line.strip())
    if "tqdm" in sys.modules:  # a progress bar may be showing: print above it, not through it
        sys.modules["tqdm"].tqdm.write(f"mesh2tex: {prefix}: {text}", file=sys.stderr)
    else:
        print(f"mesh2tex: {prefix}: {text}", file=sys.stderr)


def warning(message) -> None:
    """``mesh2tex: warning: <message>`` as one line on stderr."""
    _line("warning", message)


def note(message) -> None:
    """``mesh2tex: note: <message>`` as one line on stderr."""
    _line("note", message)

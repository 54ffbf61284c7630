"""The one error type a user sees as a single line (and a non-zero exit) instead of a traceback."""


class UserError(Exception):
    """Bad input or a bad request: the message names the file or the option and what is wrong.

    The command-line entry point prints ``mesh2tex: error: <message>`` and exits with ``exit_code``.
    Anything else that escapes is a bug and keeps its traceback.
    """

    def __init__(self, message: str, exit_code: int = 2):
        super().__init__(message)
        self.exit_code = exit_code

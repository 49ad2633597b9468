"""The one exception type for user mistakes: the CLI prints it on one line, with no traceback."""


class UserError(Exception):
    """Bad input or options from the user (missing file, unknown family, wrong column...)."""

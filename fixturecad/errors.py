"""The one error type the CLI turns into a single line on stderr and exit code 2."""


class InputError(ValueError):
    """Bad user input: a name, a number or a file that cannot be used.

    The message is one line that names the problem and, where there are
    choices, lists the valid ones.
    """

"""The two error types the CLI turns into a single line on stderr: bad input (exit 2), the machine (exit 1)."""

import errno


class InputError(ValueError):
    """Bad user input: a name, a number or a file that cannot be used.

    The message is one line that names the problem and, where there are
    choices, lists the valid ones.
    """


class EnvironmentFault(RuntimeError):
    """Not the input but the machine: a full disk. The message is one line with the reason."""


# What no other input would mend: the user frees space, not picks another folder.
_MACHINE_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EIO}


def write_error(error: OSError, what) -> Exception:
    """The one-line error of a failed write of ``what``: an EnvironmentFault for a full disk, else an
    InputError (a read-only or missing folder the user chose)."""
    message = f"cannot write {what}: {error.strerror or error}"
    return EnvironmentFault(message) if error.errno in _MACHINE_ERRNOS else InputError(message)

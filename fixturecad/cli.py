"""The ``fixturecad`` command: command groups from their own modules, one error path.

Each command module holds a ``typer.Typer`` whose commands are merged here at
the top level. Heavy imports (cadquery above all) happen inside the commands
that need them, so ``fixturecad --help`` and the theory commands start fast.
"""

import sys

import typer

from fixturecad.calibration_commands import app as calibration_app
from fixturecad.errors import InputError
from fixturecad.fixture_commands import app as fixture_app
from fixturecad.registration_commands import app as registration_app
from fixturecad.theory.commands import app as theory_app

app = typer.Typer(
    name="fixturecad",
    help="Design, build and register touch-sensing reference fixtures.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
for group in (theory_app, fixture_app, registration_app, calibration_app):
    app.add_typer(group)


def fail(message: str) -> None:
    """Print one line on stderr and exit with code 2."""
    print(f"fixturecad: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def main(argv: list[str] | None = None) -> None:
    """Console entry point: usage errors and bad input are one line, exit 2."""
    command = typer.main.get_command(app)
    try:
        code = command.main(args=argv, prog_name="fixturecad", standalone_mode=False)
    except InputError as error:
        fail(str(error))
    except (typer.Abort, KeyboardInterrupt):
        fail("aborted")
    except Exception as error:
        # Typer's usage errors (unknown option, bad value, missing argument) carry exit code 2.
        if getattr(error, "exit_code", None) == 2 and hasattr(error, "format_message"):
            fail(" ".join(error.format_message().split()))
        raise
    except BrokenPipeError:
        sys.stderr.close()
        raise SystemExit(0)
    raise SystemExit(code if isinstance(code, int) else 0)

"""The ``fixturecad`` command: command groups from their own modules, one error path.

Each command module holds a ``typer.Typer`` whose commands are merged here at
the top level. Heavy imports (cadquery above all) happen inside the commands
that need them, so ``fixturecad --help`` and the theory commands start fast.
"""

from fixturecad import interrupt

interrupt.install()  # before any other import: Ctrl-C and SIGTERM are one line from the first instruction

import sys
import warnings
from typing import Annotated

import typer

from fixturecad import __version__

from fixturecad.calibration_commands import app as calibration_app
from fixturecad.design_commands import app as design_app
from fixturecad.errors import EnvironmentFault, InputError
from fixturecad.fixture_commands import app as fixture_app
from fixturecad.plan_commands import app as plan_app
from fixturecad.registration_commands import app as registration_app
from fixturecad.theory.commands import app as theory_app

app = typer.Typer(
    name="fixturecad",
    help="Design, build and register touch-sensing reference fixtures.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
for group in (theory_app, fixture_app, design_app, plan_app, registration_app, calibration_app):
    app.add_typer(group)


def _print_version(value: bool) -> None:
    if value:
        typer.echo(f"fixturecad {__version__}")
        raise typer.Exit()


@app.callback()
def _options(
    version: Annotated[bool, typer.Option("--version", callback=_print_version, is_eager=True,
                                          help="Print the version and exit.")] = False,
):
    """Design, build and register touch-sensing reference fixtures."""


def fail(message: str, code: int = 2) -> None:
    """Print one line on stderr and exit with ``code`` (2: bad input, 1: the machine)."""
    print(f"fixturecad: error: {message}", file=sys.stderr)
    raise SystemExit(code)


def main(argv: list[str] | None = None) -> None:
    """Console entry point: usage errors and bad input are one line, exit 2; a full disk one line, exit 1."""
    command = typer.main.get_command(app)
    warnings.simplefilter("ignore")  # a user sees results and one-line errors, never Python warnings
    try:
        code = command.main(args=argv, prog_name="fixturecad", standalone_mode=False)
    except InputError as error:
        fail(str(error))
    except EnvironmentFault as error:
        fail(str(error), 1)
    except (typer.Abort, KeyboardInterrupt):
        # Ctrl-C where fixturecad.interrupt could not take it (main called off the main thread).
        sys.stderr.write(interrupt.MESSAGE.decode())
        raise SystemExit(130)
    except Exception as error:
        if type(error).__name__ == "NoArgsIsHelpError":
            raise SystemExit(0)  # the help is printed: no error to add
        # Typer's usage errors (unknown option, bad value, missing argument) carry exit code 2.
        if getattr(error, "exit_code", None) == 2 and hasattr(error, "format_message"):
            fail(" ".join(error.format_message().split()))
        raise
    except BrokenPipeError:
        sys.stderr.close()
        raise SystemExit(0)
    raise SystemExit(code if isinstance(code, int) else 0)

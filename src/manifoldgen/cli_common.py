"""What every module of the command line shares: the typer ``app`` its commands register on, the consoles, the
error handling every command wears (:func:`friendly`) and the app's own (usage errors as one line), the help texts
of the task options and the tasks they name. Importing it limits the thread pools first (see
:func:`manifoldgen.runtime.limit_threads`)."""

from __future__ import annotations

import contextlib
import functools
import signal
import sys
import threading
import warnings

from manifoldgen.runtime import check_seed, limit_threads

limit_threads()  # before numpy and torch start their pools: on a busy machine, spinning threads slowed collect 18x

import typer  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.text import Text  # noqa: E402
from typer.core import TyperGroup  # noqa: E402

from manifoldgen.errors import ManifoldgenError, user_code  # noqa: E402

console = Console(soft_wrap=True)  # results
errors = Console(soft_wrap=True, stderr=True)  # errors and warnings
_click = sys.modules[typer.BadParameter.__module__]  # click's exceptions: typer's own copy of click, or click


for _stream in (sys.stdout, sys.stderr):  # a name the terminal cannot encode is printed escaped, never a traceback
    if hasattr(_stream, "reconfigure"):
        _stream.reconfigure(errors="backslashreplace")


def one_line(message: str) -> str:
    """``message`` with its control characters (a newline in a user's label or file name) escaped: one line."""
    return "".join(ch if ch.isprintable() else ch.encode("unicode_escape").decode("ascii") for ch in message)


def say_error(message: str) -> None:
    """Print ``message`` as the one ``error:`` line (verbatim: no markup; control characters escaped)."""
    errors.print(Text.assemble(("error: ", "red"), one_line(message)))


@contextlib.contextmanager
def _usage_in_one_line():
    """A usage error (a missing option, a value of the wrong type, an unknown option) as one ``error:`` line and
    exit code 2, as every other error."""
    try:
        yield
    except getattr(_click, "NoArgsIsHelpError", ()):
        raise  # no arguments: the help
    except _click.UsageError as exc:
        message = exc.format_message().rstrip(".")
        command = exc.ctx.command_path if exc.ctx is not None else "manifoldgen"
        say_error(f"{message[:1].lower()}{message[1:]}; see `{command} --help`")
        raise typer.Exit(2) from None


class OneLineUsage(TyperGroup):
    """The command group: its usage errors (and its subcommands') are one line (see :func:`_usage_in_one_line`)."""

    def make_context(self, *args, **kwargs):
        with _usage_in_one_line():
            return super().make_context(*args, **kwargs)

    def invoke(self, ctx):
        with _usage_in_one_line():
            return super().invoke(ctx)


app = typer.Typer(cls=OneLineUsage, add_completion=False, no_args_is_help=True, rich_markup_mode=None,
                  help="Constrained motion planning with learned samplers.")


def friendly(command):
    """Turn ManifoldgenError (and an OS error no library call turned into one) into a one-line error on stderr and
    exit code 2; warnings print in yellow, on stderr too. Every command's ``seed`` is range-checked here."""
    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        def show(message, category, filename, lineno, file=None, line=None):
            errors.print(Text.assemble(("warning: ", "yellow"), str(message)))
        warnings.showwarning = show
        stop = _stopped_cleanly()
        try:
            if "seed" in kwargs:
                check_seed(kwargs["seed"])
            return command(*args, **kwargs)
        except ManifoldgenError as exc:
            say_error(str(exc))
            raise typer.Exit(2) from None
        except OSError as exc:
            where = f"{exc.filename}: " if exc.filename else ""
            say_error(f"{where}{exc.strerror or exc}; check the path and its permissions")
            raise typer.Exit(2) from None
        except KeyboardInterrupt as exc:  # Ctrl-C, SIGINT, or a user's module raising it: one line, exit 130
            blamed = user_code(exc)
            say_error(f"user code {blamed} raised KeyboardInterrupt; stopped (fix that module if Ctrl-C was not "
                      "pressed)" if blamed else "interrupted (Ctrl-C); stopped")
            raise typer.Exit(130) from None
        except (Exception, SystemExit) as exc:
            blamed = user_code(exc)
            if blamed is None or isinstance(exc, (typer.Exit, typer.Abort, Terminated)):
                raise
            why = str(exc).strip().splitlines()[0][:200] if str(exc).strip() else ""
            say_error(f"user code {blamed} raised {type(exc).__name__}{': ' + why if why else ''}; fix that module "
                      "(see docs/tasks.md)")
            raise typer.Exit(2) from None
        finally:
            stop()
    return wrapper


class Terminated(SystemExit):
    """The exit a SIGTERM raises (code 128 + the signal), wherever the command was: never a user module's fault."""


def _terminated(signum, frame):
    raise Terminated(128 + signum)


def _stopped_cleanly():
    """Make SIGTERM stop the command as Ctrl-C does, through its ``finally`` blocks (a lock released, a temporary
    file removed) and with exit code 143; returns what puts the previous handler back."""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGTERM) != signal.SIG_DFL:
        return lambda: None
    signal.signal(signal.SIGTERM, _terminated)
    return lambda: signal.signal(signal.SIGTERM, signal.SIG_DFL)


TASK_HELP = "Built-in task name (see `manifoldgen tasks`) or a task .toml file"
ROBOT_HELP = "Robot of a built-in task (default: the task's default robot)"
MADE_FOR_HELP = ("The task the input file was made for (refused unless it matches the file's); needed when the file "
                 "names a user's module:Class constraint, whose module is then imported from this task file: "
                 + TASK_HELP)
TRUST_HELP = ("Import a module:Class constraint the input file names from PYTHONPATH without its task file: this "
              "EXECUTES that module's code; only for files you trust (prefer --task)")


def load_task(task: str, robot: str | None):
    """The task a ``TASK`` argument names: a built-in task (for ``robot``) or a task file."""
    from manifoldgen.tasks import get_task
    if robot is not None and not robot.strip():
        raise ManifoldgenError("--robot is empty; give a robot name (`manifoldgen robots` lists them) or leave "
                               "--robot out for the task's default robot")
    return get_task(task, robot)


def made_for(task: str | None, robot: str | None = None):
    """The task given for an input file (``--task``), or None: the file's own, from its meta."""
    return None if task is None else load_task(task, robot)

"""What every module of the command line shares: the typer ``app`` its commands register on, the console, the
error handling every command wears (:func:`friendly`), the help texts of the task options and the tasks they
name. Importing it limits the thread pools first (see :func:`manifoldgen.runtime.limit_threads`)."""

from __future__ import annotations

import functools
import warnings

from manifoldgen.runtime import check_seed, limit_threads

limit_threads()  # before numpy and torch start their pools: on a busy machine, spinning threads slowed collect 18x

import typer  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.text import Text  # noqa: E402

from manifoldgen.errors import ManifoldgenError, user_code  # noqa: E402

app = typer.Typer(add_completion=False, no_args_is_help=True, rich_markup_mode=None,
                  help="Constrained motion planning with learned samplers.")
console = Console(soft_wrap=True)


def friendly(command):
    """Turn ManifoldgenError (and an OS error no library call turned into one) into a one-line error and
    exit code 2; warnings print in yellow. Every command's ``seed`` is range-checked here."""
    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        def show(message, category, filename, lineno, file=None, line=None):
            console.print(Text.assemble(("warning: ", "yellow"), str(message)))
        warnings.showwarning = show
        try:
            if "seed" in kwargs:
                check_seed(kwargs["seed"])
            return command(*args, **kwargs)
        except ManifoldgenError as exc:
            console.print(Text.assemble(("error: ", "red"), str(exc)))  # verbatim: no markup
            raise typer.Exit(2) from None
        except OSError as exc:
            where = f"{exc.filename}: " if exc.filename else ""
            console.print(Text.assemble(("error: ", "red"), f"{where}{exc.strerror or exc}; check the path and its "
                                        "permissions"))
            raise typer.Exit(2) from None
        except (Exception, SystemExit) as exc:
            blamed = user_code(exc)
            if blamed is None or isinstance(exc, (typer.Exit, typer.Abort)):
                raise
            why = str(exc).strip().splitlines()[0][:200] if str(exc).strip() else ""
            console.print(Text.assemble(("error: ", "red"), f"user code {blamed} raised {type(exc).__name__}"
                                        f"{': ' + why if why else ''}; fix that module (see docs/tasks.md)"))
            raise typer.Exit(2) from None
    return wrapper


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
    return get_task(task, robot)


def made_for(task: str | None, robot: str | None = None):
    """The task given for an input file (``--task``), or None: the file's own, from its meta."""
    return None if task is None else load_task(task, robot)

"""The installed package: an optional extra that is missing is one line naming it (through the CLI), and the
compiled core is used only with the pinocchio it was built against."""

import shutil
import subprocess
import sys

import pinocchio as pin
import pytest
from typer.testing import CliRunner

from manifoldgen import core_extension
from manifoldgen.cli import app
from manifoldgen.errors import ManifoldgenError, require
from manifoldgen.models import pretrained_model_dir

runner = CliRunner()
CVAE = f"cvae:{pretrained_model_dir()}"


def says_the_extra(result, extra: str, what: str) -> bool:
    """The command failed (exit 2) with the one-line error naming ``extra`` as its last line, no traceback."""
    line = f"error: {what} needs the [{extra}] extra: pip install 'manifoldgen[{extra}]'"
    return result.exit_code == 2 and result.output.strip().splitlines()[-1] == line and "Traceback" not in result.output


def without_ompl(monkeypatch) -> None:
    """Make ``import ompl`` and its submodules raise ImportError, as if OMPL were not installed (submodules another
    test imported included)."""
    for name in ["ompl", *(name for name in sys.modules if name.startswith("ompl."))]:
        monkeypatch.setitem(sys.modules, name, None)


def test_require_names_the_extra_and_lets_other_import_errors_through(monkeypatch, tmp_path):
    without_ompl(monkeypatch)
    with pytest.raises(ManifoldgenError, match=r"^the OMPL bridge needs the \[ompl\] extra: "
                                               r"pip install 'manifoldgen\[ompl\]'$"):
        require("ompl.base", "ompl", "the OMPL bridge")
    (tmp_path / "broken_extra.py").write_text("import no_such_dependency\n")  # installed, but broken
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ModuleNotFoundError, match="no_such_dependency"):
        require("broken_extra", "viewer", "the viewer")


@pytest.mark.parametrize("module, extra, what", [
    ("viser", "viewer", "the viewer"),
    ("toppra", "trajectory", "time parameterization (TOPP-RA)"),
])
def test_a_missing_extra_is_one_line_through_the_cli(module, extra, what, monkeypatch, planned_path, tmp_path):
    path = planned_path("wall")
    monkeypatch.setitem(sys.modules, module, None)
    args = {"viewer": ["view", str(path)],
            "trajectory": ["trajectory", str(path), "-o", str(tmp_path / "traj.json")]}[extra]
    result = runner.invoke(app, args)
    assert says_the_extra(result, extra, what), result.output


def test_missing_ompl_is_one_line_through_the_cli(monkeypatch, tmp_path):
    without_ompl(monkeypatch)
    monkeypatch.delitem(sys.modules, "manifoldgen.ompl_bridge", raising=False)  # imported afresh
    result = runner.invoke(app, ["bench", "plan", "pose", "--scene", "wall", "--runs", "1", "-m",
                                 "ompl-projected-rrtconnect", "-o", str(tmp_path / "bench")])
    assert says_the_extra(result, "ompl", "the OMPL bridge"), result.output


def test_the_cpp_baseline_needs_no_ompl_python_bindings(monkeypatch):
    """The C++ OMPL baseline runs its own program: without the [ompl] extra it still imports and writes problems."""
    without_ompl(monkeypatch)
    for module in ("manifoldgen.ompl_bridge", "manifoldgen.ompl_native"):
        monkeypatch.delitem(sys.modules, module, raising=False)  # imported afresh
    import manifoldgen.ompl_native as ompl_native
    assert ompl_native.OmplSettings().range > 0 and "manifoldgen.ompl_bridge" not in sys.modules


def test_missing_zuko_is_one_line_through_the_cli(monkeypatch, tmp_path):
    data = tmp_path / "pose.npz"
    assert runner.invoke(app, ["collect", "pose", "--per-condition", "5", "-o", str(data)]).exit_code == 0
    monkeypatch.setitem(sys.modules, "zuko", None)
    result = runner.invoke(app, ["train", str(data), "--model", "flow", "-o", str(tmp_path / "flow")])
    assert says_the_extra(result, "flow", "the flow model"), result.output


def test_the_core_records_the_pinocchio_it_was_built_against():
    core = pytest.importorskip("manifoldgen_core", reason="the compiled core is not built (scripts/setup.sh builds it)")
    assert core.PINOCCHIO_VERSION == pin.__version__
    assert core_extension.core_problem() == "" and core_extension.core_module() is core


@pytest.mark.skipif(shutil.which("readelf") is None, reason="readelf (binutils) is not installed")
def test_the_core_has_no_build_path_in_its_runpath():
    core = pytest.importorskip("manifoldgen_core", reason="the compiled core is not built (scripts/setup.sh builds it)")
    dynamic = subprocess.run(["readelf", "-d", core.__file__], capture_output=True, text=True, check=True).stdout
    paths = [p for line in dynamic.splitlines() if "RUNPATH" in line or "RPATH" in line
             for p in line.split("[", 1)[1].rstrip("]").split(":")]
    assert paths and all(p.startswith("$ORIGIN") for p in paths), paths


def test_a_core_built_against_another_pinocchio_is_refused(monkeypatch, tmp_path):
    core = pytest.importorskip("manifoldgen_core", reason="the compiled core is not built (scripts/setup.sh builds it)")
    monkeypatch.setattr(core, "PINOCCHIO_VERSION", "0.0.1")
    problem = core_extension.core_problem()
    assert problem.startswith(f"the compiled core was built against pinocchio 0.0.1 but pinocchio {pin.__version__} "
                              "is installed") and "--no-build-isolation" in problem and "\n" not in problem
    assert core_extension.core_module() is None
    auto = runner.invoke(app, ["plan", "pose", "--scene", "wall", "--sampler", CVAE, "-o", str(tmp_path / "a.npz")])
    assert auto.exit_code == 0 and f"Python search ({problem})" in auto.output, auto.output
    asked = runner.invoke(app, ["plan", "pose", "--scene", "wall", "--sampler", CVAE, "--set", "core=native",
                                "-o", str(tmp_path / "n.npz")])
    assert asked.exit_code == 2 and asked.output.strip().splitlines() == [f"error: {problem}"], asked.output


def test_a_missing_core_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "manifoldgen_core", None)  # import manifoldgen_core now raises ImportError
    assert core_extension.core_problem() == f"the compiled core manifoldgen_core is not installed; {core_extension.BUILD_HINT}"
    assert core_extension.core_module() is None

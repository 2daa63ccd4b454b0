"""The ``view`` and ``trajectory`` commands (registered on :data:`manifoldgen.cli_common.app`)."""

from __future__ import annotations

import time
from pathlib import Path

import typer

from manifoldgen.cli_common import MADE_FOR_HELP, TRUST_HELP, app, console, friendly, made_for
from manifoldgen.errors import ManifoldgenError

TRAJECTORY_FORMATS = (".json", ".csv")


@app.command()
@friendly
def view(file: Path = typer.Argument(..., help="A path, dataset or sample .npz, a scene .json, a task .toml or a "
                                     "built-in task name"),
         host: str = typer.Option("127.0.0.1", help="Address to serve on (0.0.0.0: every interface)"),
         port: int = typer.Option(8080, help="Port to serve on (the next free one if it is taken)"),
         task: str = typer.Option(None, help="Task of a scene .json (default: the built-in task that lists it, "
                                  "else pose), or of an .npz (default: its own, from its meta; needed for a user's "
                                  "module:Class constraint, and checked against the file)"),
         trust_code: bool = typer.Option(False, "--trust-code", help=TRUST_HELP),
         export: Path = typer.Option(None, help="Write one self-contained .html page that replays the scene "
                                     "offline, instead of serving"),
         snapshots: Path = typer.Option(None, help="Write a .png strip of robot snapshots along a path, instead "
                                        "of serving")):
    """Show a file in the browser (viser): a path animated, a dataset's rows, a scene's start and goal."""
    from manifoldgen.io import check_output_path
    start = time.perf_counter()
    if export is not None and snapshots is not None:
        raise ManifoldgenError("--export and --snapshots each write one file instead of serving; give one of them "
                               "per run")
    for out, option, suffix in ((export, "--export", ".html"), (snapshots, "--snapshots", ".png")):
        if out is not None:
            check_output_path(out, [file], what=option, suffixes=(suffix,))
    if export is not None:
        from manifoldgen.viewer.export import export_html
        info = export_html(file, export, task, trust_code=trust_code)
        if info["note"]:
            console.print(info["note"], markup=False)
        console.print(f"wrote {export}: {info['bytes'] / 1e6:.1f} MB, {info['frames']} frames "
                      f"({info['seconds']:.1f} s of replay); open it in a browser, no server needed", markup=False)
        return
    if snapshots is not None:
        from manifoldgen.viewer.source import read_source
        from manifoldgen.viz.snapshots import draw_snapshots
        source = read_source(file, task, trust_code=trust_code)
        if source.kind != "path":
            raise ManifoldgenError(f"--snapshots needs a path file (made by `manifoldgen plan`), not {file}")
        draw_snapshots(source.q, source.task, source.scene, snapshots)
        console.print(f"wrote {snapshots} in {time.perf_counter() - start:.1f} s", markup=False)
        return
    from manifoldgen.viewer.server import open_viewer, serve
    viewer = open_viewer(file, host, port, task, say=lambda line: console.print(line, markup=False),
                         trust_code=trust_code)
    shown = "localhost" if host == "0.0.0.0" else host
    console.print(f"viewer of {file} ready in {time.perf_counter() - start:.1f} s at "
                  f"http://{shown}:{viewer.server.get_port()} (Ctrl-C to stop)", markup=False, highlight=False)
    serve(viewer)


@app.command()
@friendly
def trajectory(path_file: Path = typer.Argument(..., help="Path .npz made by `manifoldgen plan`"),
               vel_scale: float = typer.Option(1.0, help="Fraction (0.001 to 1) of the URDF joint velocity "
                                               "limits"),
               acc_scale: float = typer.Option(1.0, help="Fraction (0.001 to 1) of the reference acceleration limits "
                                               "(2 x the velocity limit per second)"),
               dt: float = typer.Option(0.01, help="Seconds between samples"),
               output: Path = typer.Option(..., "-o", "--output", help="traj.json (ROS JointTrajectory layout) "
                                           "or traj.csv"),
               task: str = typer.Option(None, help=MADE_FOR_HELP),
               trust_code: bool = typer.Option(False, "--trust-code", help=TRUST_HELP)):
    """Time-parameterise a path with TOPP-RA within joint limits; every sample is rechecked."""
    from manifoldgen.io import check_output_path
    from manifoldgen.trajectory import trajectory_of_file
    check_output_path(output, [path_file], suffixes=TRAJECTORY_FORMATS, kind="trajectory")
    traj = trajectory_of_file(path_file, vel_scale, acc_scale, dt, task=made_for(task), trust_code=trust_code)
    info, check = traj.info, traj.info["check"]
    if check["first_invalid"] is not None:
        bad = check["first_invalid"]
        raise ManifoldgenError(f"{check['states'] - check['valid']} of {check['states']} trajectory states are "
                               f"invalid, the first at {bad['time']:.2f} s: it {bad['problem']}; nothing written "
                               "(check the path with examples/check_path.py)")
    if check["first_invalid_motion"] is not None:
        bad = check["first_invalid_motion"]
        raise ManifoldgenError(f"every trajectory state is valid, but the straight motion from the sample at "
                               f"{bad['time']:.2f} s to the next is not ({bad['problem']}); nothing written: give a "
                               f"smaller --dt than {dt:g} s")
    traj.save(output)
    console.print(f"trajectory: {info['duration']:.2f} s for a path of {info['path_length']:.2f} rad "
                  f"({info['waypoints']} waypoints) | {check['states']} states every <= {dt:g} s and the motions "
                  f"between them: 100.0% valid (worst constraint use {check['worst_violation']:.2f} of tolerance, "
                  f"limits and collisions checked) | velocity <= {vel_scale:g} x URDF, acceleration <= "
                  f"{acc_scale:g} x reference; TOPP-RA timing stretched x{info['stretch_after_toppra']:.2f} -> {output}", markup=False,
                  highlight=False)

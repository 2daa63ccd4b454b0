"""Serve a file's scene in the browser: ``manifoldgen view FILE [--host --port]``."""

from __future__ import annotations

import contextlib
import errno
import io
import signal
import socket
import threading
from collections.abc import Callable
from pathlib import Path

from manifoldgen.errors import ManifoldgenError
from manifoldgen.viewer.scene import FPS, Viewer, build_scene
from manifoldgen.viewer.source import read_source

PORT_TRIES = 50


def free_port(host: str, port: int) -> int:
    """``port`` if it can be bound on ``host``, else the next free one (up to PORT_TRIES later)."""
    if not 0 < port < 65536:
        raise ManifoldgenError(f"--port must be between 1 and 65535, got {port}")
    for candidate in range(port, min(port + PORT_TRIES, 65536)):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server binds: TIME_WAIT is free
            try:
                s.bind((host, candidate))
                return candidate
            except OSError as exc:
                if exc.errno == errno.EADDRNOTAVAIL:
                    raise ManifoldgenError(f"cannot serve on host {host}: not an address of this machine; use "
                                           "127.0.0.1 (this machine only) or 0.0.0.0 (every interface)") from exc
    raise ManifoldgenError(f"ports {port} to {candidate} on {host} are all in use; pass another --port")


def start_server(host: str, port: int):
    """A viser server on ``host``:``port`` (0: any free port), its banner silenced (callers say the
    URL), lit by a hemisphere light without shadows instead of an environment map: a browser
    without a GPU draws the first frame in 2 s instead of 8."""
    import viser

    with contextlib.redirect_stdout(io.StringIO()):
        server = viser.ViserServer(host=host, port=port, verbose=False)
    server.gui.configure_theme(control_width="large", show_share_button=False)
    server.gui.main_panel.dock_right()
    server.scene.configure_environment_map(None)
    server.scene.configure_default_lights(enabled=True, cast_shadow=False)
    server.scene.add_light_hemisphere("/light", sky_color=(255, 255, 255), ground_color=(110, 110, 120),
                                      intensity=1.8)
    return server


def stop_server(server, wait: float = 0.5) -> None:
    """Stop serving; wait at most ``wait`` s for the server thread (viser waits 6 s when a browser has
    left an idle connection open: its thread, a daemon, winds down alone)."""
    stopper = threading.Thread(target=server.stop, daemon=True)
    with contextlib.redirect_stdout(io.StringIO()):  # viser's "Server stopped"
        stopper.start()
        stopper.join(wait)


def open_viewer(file: str | Path, host: str = "127.0.0.1", port: int = 8080, task: str | None = None,
                say: Callable[[str], None] = print, *, trust_code: bool = False) -> Viewer:
    """Start a viser server on ``host``:``port`` (or the next free port, said) showing ``file`` (``task``,
    ``trust_code``: see :func:`~manifoldgen.viewer.source.read_source`)."""
    source = read_source(file, task, trust_code=trust_code)
    chosen = free_port(host, port)
    if chosen != port:
        say(f"port {port} is in use; using {chosen}")
    viewer = build_scene(start_server(host, chosen), source)
    if viewer.note:
        say(viewer.note)
    return viewer


def serve(viewer: Viewer) -> None:
    """Run the animation (when ``play`` is ticked) until Ctrl-C or SIGTERM; then close the server. The signals
    only set a flag the loop reads between frames: an interrupt raised inside a viser call could leave one of
    its locks held, and the process would then hang at exit."""
    stop = threading.Event()
    handlers = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        while not stop.wait(1 / FPS):
            if viewer.play is not None and viewer.play.value:
                viewer.slider.value = (int(viewer.slider.value) + 1) % len(viewer.frames)  # moves the robot
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
        stop_server(viewer.server)

"""Serve a file's scene in the browser: ``manifoldgen view FILE [--host --port]``."""

from __future__ import annotations

import contextlib
import errno
import io
import ipaddress
import signal
import socket
import threading
from collections.abc import Callable
from pathlib import Path
from urllib.parse import urlsplit

from manifoldgen.errors import ManifoldgenError, require
from manifoldgen.viewer.scene import FPS, Viewer, build_scene
from manifoldgen.viewer.source import read_source

PORT_TRIES = 50
ORIGIN_REFUSED = 1008  # websocket close code: policy violation


def free_port(host: str, port: int) -> int:
    """``port`` if it can be bound on ``host``, else the next free one (up to PORT_TRIES later)."""
    if not 0 < port < 65536:
        raise ManifoldgenError(f"--port must be between 1 and 65535, got {port}")
    try:
        socket.getaddrinfo(host, None, socket.AF_INET)
    except (socket.gaierror, UnicodeError) as exc:
        raise ManifoldgenError(f"cannot serve on host {host!r}: not an IPv4 address or a known host name ({exc}); "
                               "use 127.0.0.1 (this machine only) or 0.0.0.0 (every interface)") from None
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
                if exc.errno != errno.EADDRINUSE:
                    raise ManifoldgenError(f"cannot serve on host {host}, port {candidate}: {exc.strerror}") from exc
    raise ManifoldgenError(f"ports {port} to {candidate} on {host} are all in use; pass another --port")


def start_server(host: str, port: int):
    """A viser server on ``host``:``port`` (0: any free port), its banner silenced (callers say the
    URL), lit by a hemisphere light without shadows instead of an environment map: a browser
    without a GPU draws the first frame in 2 s instead of 8. Only the viewer's own page may open its
    websocket (:func:`guard_origin`)."""
    viser = require("viser", "viewer", "the viewer")

    with contextlib.redirect_stdout(io.StringIO()):
        server = viser.ViserServer(host=host, port=port, verbose=False)
    guard_origin(server, host)
    server.gui.configure_theme(control_width="large", show_share_button=False)
    server.gui.main_panel.dock_right()
    server.scene.configure_environment_map(None)
    server.scene.configure_default_lights(enabled=True, cast_shadow=False)
    server.scene.add_light_hemisphere("/light", sky_color=(255, 255, 255), ground_color=(110, 110, 120),
                                      intensity=1.8)
    return server


def _host_port(url: str) -> tuple[str, int] | None:
    """(host name, port) of an ``http(s)://host[:port]`` origin, None if it is not one."""
    try:
        parts = urlsplit(url)
        port = parts.port or {"http": 80, "https": 443}.get(parts.scheme)
    except ValueError:
        return None
    return (parts.hostname, port) if parts.scheme in ("http", "https") and parts.hostname and port else None


def origin_allowed(origin: str | None, host_header: str | None, served_host: str = "127.0.0.1") -> bool:
    """Whether a websocket handshake comes from the viewer's own page: its ``Origin`` is the host and port the
    browser reached this server at (the ``Host`` header; through a tunnel too), named by an IP address,
    localhost, this machine's name or ``served_host``; any other name could be a foreign site's, rebound to
    this address. A handshake without ``Origin`` is no browser's (browsers always send one): allowed, as any
    program that reaches the port can connect anyway."""
    if origin is None:
        return True
    page, reached = _host_port(origin), _host_port(f"http://{host_header}") if host_header else None
    if page is None or page != reached:
        return False
    name = page[0].lower()
    try:
        ipaddress.ip_address(name)
        return True
    except ValueError:
        return name in ("localhost", socket.gethostname().lower(), served_host.lower())


def guard_origin(server, host: str) -> None:
    """Close every websocket whose Origin is not the viewer's own page (:func:`origin_allowed`) before a message
    passes either way: otherwise a page of any site open in the browser could read the scene and move the
    controls. viser has no handshake hook: the check is its first connect callback, which runs before the
    connection's senders and receiver start."""
    sockets = server._websock_server  # viser's websocket server (no public handle)

    async def check(client) -> None:
        connection = sockets._live_connections[client.client_id]
        headers = connection.request.headers
        if not origin_allowed(headers.get("Origin"), headers.get("Host"), host):
            await connection.close(ORIGIN_REFUSED, "origin not allowed: open the viewer's own address")

    sockets._client_connect_cb.insert(0, check)
    sockets.disconnect_all_clients()  # one that connected before the check was in place reconnects through it


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

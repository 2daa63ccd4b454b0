"""One self-contained HTML page that replays a file's scene offline: ``view FILE --export out.html``.

viser records the scene's messages (meshes, poses) with the time between them and embeds the
recording, compressed, in its single-file client (``StateSerializer.as_html``): the page needs no
server and no network. A path plays in a loop (play/pause and a time bar), a dataset steps the
robot through up to ``EXPORT_ROWS`` rows, a scene or task is static. The GUI panel (plot,
sliders) is not recorded.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from manifoldgen.io import GENERATOR_MARK, atomic_write_text, check_output_path
from manifoldgen.viewer.scene import FPS, build_scene
from manifoldgen.viewer.server import start_server, stop_server
from manifoldgen.viewer.source import read_source

EXPORT_ROWS = 60
ROW_SECONDS = 0.5


def export_html(file: str | Path, out: str | Path, task: str | None = None, *, trust_code: bool = False) -> dict:
    """Write the page (``task``, ``trust_code``: see :func:`~manifoldgen.viewer.source.read_source`); returns
    ``{"bytes", "frames", "seconds", "note"}``."""
    out = check_output_path(out)
    source = read_source(file, task, trust_code=trust_code)
    server = start_server("127.0.0.1", 0)
    try:
        viewer = build_scene(server, source)
        recording = server.get_scene_serializer()
        if source.kind == "path":
            frames, pause = np.arange(len(viewer.frames)), 1 / FPS
        elif source.kind == "dataset":
            frames, pause = np.unique(np.linspace(0, len(viewer.frames) - 1, EXPORT_ROWS).astype(int)), ROW_SECONDS
        else:
            frames, pause = np.zeros(0, int), 0.0
        for i in frames:
            viewer.show(i)
            recording.insert_sleep(pause)
        page = recording.as_html()
    finally:
        stop_server(server)
    page = page.replace("<title>Viser</title>", f"<title>{html.escape(source.title)}</title>", 1)
    page = page.replace("<head>", f"<head>\n    {GENERATOR_MARK}", 1)  # what lets a later export replace it
    atomic_write_text(out, page)
    out.chmod(0o644)  # a page to share (the atomic write leaves it private)
    return {"bytes": len(page.encode()), "frames": len(frames), "seconds": len(frames) * pause, "note": viewer.note}

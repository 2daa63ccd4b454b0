"""``manifoldgen view``: the viser scene of each file kind, what a real browser (headless Chromium)
draws of it, the offline page of ``--export``, and one clear line per bad input."""

from __future__ import annotations

import base64
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import msgspec
import numpy as np
import pytest
import zstandard
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import load_npz, save_npz
from manifoldgen.robot import Robot
from manifoldgen.viewer.browser import CHROMIUM, Browser, drawn_fraction
from manifoldgen.viewer.export import export_html
from manifoldgen.viewer.meshes import robot_parts
from manifoldgen.viewer.server import free_port, open_viewer, start_server, stop_server

pytestmark = pytest.mark.slow  # the quick loop (pytest -m "not slow") leaves this module out

runner = CliRunner()
SCENES = Path(__file__).resolve().parents[1] / "src/manifoldgen/tasks/scenes"
needs_chromium = pytest.mark.skipif(not CHROMIUM.exists(), reason=f"{CHROMIUM} is not installed "
                                    "(Debian: apt-get install -y chromium); the browser tests need it")


@pytest.fixture(scope="module")
def maze(planned_path) -> Path:
    """A planned path of the panda maze scene (obstacles and a held tool)."""
    return planned_path("maze")


@pytest.fixture(scope="module")
def browser():
    with Browser(width=640, height=480) as b:
        yield b


@pytest.fixture(scope="module")
def empty_fraction(browser) -> float:
    """How much of the 3D view an empty viser scene draws (axes gizmo, notices)."""
    server = start_server("127.0.0.1", free_port("127.0.0.1", 8600))
    try:
        browser.open(f"http://127.0.0.1:{server.get_port()}")
        image, _ = browser.settled_canvas()
    finally:
        stop_server(server)
    return drawn_fraction(image)


def test_path_scene_holds_robot_meshes_obstacles_tool_trace_and_controls(maze):
    viewer = open_viewer(maze, port=free_port("127.0.0.1", 8610), say=lambda _: None)
    try:
        scene = viewer.server.scene
        assert viewer.source.kind == "path" and viewer.note == ""
        for name in ("/robot/panda_joint1/panda_link1_0", "/obstacles/0_outer_near", "/obstacles/5_inner_right",
                     "/trace/panda_hand_tcp"):
            assert scene.get_handle_by_name(name) is not None, name
        assert scene.get_handle_by_name("/robot/panda_joint7/held_tool") is not None, "the tool rides on the wrist"
        hand = scene.get_handle_by_name("/robot/panda_joint7")
        assert viewer.slider.max == len(viewer.frames) - 1 > len(viewer.source.q)
        before = np.array(hand.position)
        viewer.slider.value = viewer.slider.max  # moving the time slider moves the robot
        assert np.linalg.norm(np.array(hand.position) - before) > 0.05
    finally:
        stop_server(viewer.server)


def test_dataset_samples_and_scene_views(tmp_path):
    rows = tmp_path / "d.npz"
    assert runner.invoke(app, ["collect", "pose", "--per-condition", "10", "-o", str(rows)]).exit_code == 0
    meta, arrays = load_npz(rows, ("q", "y"))
    q = arrays["q"].copy()
    q[:5, 0] += 0.5  # five rows off the manifold
    save_npz(tmp_path / "s.npz", meta, q=q, y=arrays["y"])
    for file, invalid in ((rows, False), (tmp_path / "s.npz", True)):
        viewer = open_viewer(file, port=free_port("127.0.0.1", 8620), say=lambda _: None)
        try:
            scene = viewer.server.scene
            assert viewer.source.kind == "dataset" and len(viewer.frames) == len(q)
            assert scene.get_handle_by_name("/rows/valid") is not None
            assert scene.get_handle_by_name("/rows/frames") is not None
            assert (scene.get_handle_by_name("/rows/invalid") is not None) == invalid
            assert viewer.slider.max == len(q) - 1
        finally:
            stop_server(viewer.server)
    viewer = open_viewer(SCENES / "panda-wall.json", port=free_port("127.0.0.1", 8630), say=lambda _: None)
    try:
        assert viewer.source.kind == "scene"
        for name in ("/robot/panda_joint1/panda_link1_0", "/goal/panda_joint1/panda_link1_0", "/obstacles/0_wall_left"):
            assert viewer.server.scene.get_handle_by_name(name) is not None, name
    finally:
        stop_server(viewer.server)


@needs_chromium
def test_view_command_draws_the_robot_in_headless_chromium(maze, browser, empty_fraction):
    """The real command, on a taken port: it says so, serves the next one, and Chromium draws the scene."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        command = [str(Path(sys.executable).with_name("manifoldgen")), "view", str(maze), "--port", str(port)]
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            lines = []
            for line in process.stdout:
                lines.append(line)
                if "http://" in line:
                    break
            output = "".join(lines)
            assert f"port {port} is in use; using" in output, output
            url = re.search(r"http://\S+", output).group(0)
            browser.open(url)
            image, _ = browser.settled_canvas(minimum=empty_fraction + 0.04)
        finally:
            process.send_signal(signal.SIGINT)
            process.wait(60)  # a loaded machine can take long to shut the server down
    drawn = drawn_fraction(image)
    assert drawn > 2 * empty_fraction + 0.03, (drawn, empty_fraction)
    red = (image[..., 0] > 150) & (image[..., 1] < 90) & (image[..., 2] < 90)
    assert red.sum() > 30, "the red held tool is drawn"
    assert process.returncode == 0


@needs_chromium
def test_exported_page_replays_offline(maze, tmp_path, browser, empty_fraction):
    page = tmp_path / "maze.html"
    info = export_html(maze, page)
    assert info["frames"] > 100 and 1e5 < info["bytes"] < 2e7
    recording = _recording(page.read_text())
    assert recording["durationSeconds"] > 1
    names = {m.get("name") for _, m in recording["messages"] if m.get("type") == "MeshMessage"}
    assert {"/obstacles/0_outer_near", "/robot/panda_joint7/held_tool"} <= names
    assert sum(n.startswith("/robot/") for n in names) >= 11
    browser.open(page.as_uri())
    image, _ = browser.settled_canvas(minimum=empty_fraction + 0.03)
    assert drawn_fraction(image) > empty_fraction + 0.02
    remote = [u for u in browser.requests() if not u.startswith(("file:", "data:", "blob:"))]
    assert remote == [], f"the page fetched {remote}"


def _recording(html: str) -> dict:
    """The scene recording viser embeds in an exported page (base64 of zstd of msgpack)."""
    blob = base64.b64decode(re.search(r'__VISER_EMBED_DATA__="([^"]+)"', html).group(1))
    inner = zstandard.ZstdDecompressor().decompress(blob[8:], max_output_size=int.from_bytes(blob[:8], "little"))
    return msgspec.msgpack.decode(inner[8:8 + int.from_bytes(inner[:8], "little")])


def test_missing_visual_meshes_fall_back_to_collision_geometry(tmp_path, panda_task):
    urdf = tmp_path / "panda_nomesh.urdf"
    text = Path(panda_task.robot.urdf_path).read_text()
    urdf.write_text(re.sub(r'(<visual>.*?filename=")[^"]*"', r'\1package://nowhere/missing.dae"', text, flags=re.S))
    robot = Robot.load(str(urdf), panda_task.robot.joints)
    parts, note = robot_parts(robot)
    assert "missing.dae not found" in note and "collision geometry" in note
    assert len(parts) == len(robot.collision_model.geometryObjects) and all(len(p.faces) for p in parts)


def test_bad_inputs_get_one_line(tmp_path, maze):
    (tmp_path / "notes.txt").write_text("hello")
    for args, expected in ((["view", str(tmp_path / "notes.txt")], "unknown file kind '.txt'"),
                           (["view", str(tmp_path / "none.npz")], "file not found"),
                           (["view", str(maze), "--port", "0"], "--port must be between 1 and 65535"),
                           (["view", str(maze), "--export", str(tmp_path / "no" / "x.html")], "does not exist")):
        result = runner.invoke(app, args)
        assert result.exit_code == 2 and expected in result.output and result.output.count("\n") == 1, result.output
    with pytest.raises(ManifoldgenError, match="not an address of this machine"):
        free_port("192.0.2.1", 8080)
    with pytest.raises(ManifoldgenError, match="'999.1.1.1': not an IPv4 address or a known host name"):
        free_port("999.1.1.1", 8080)  # not "all ports in use"


def test_free_port_skips_a_listening_port():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert free_port("127.0.0.1", port) > port

"""Browser viewer (meshcat): the bodies, the world, the contact points and the force arrows, live or
as a self-contained replay page.

Each body is drawn in its colour (``BodyLayout.color``) under its own node, ``bodies/<body>``, which
the page's controls show or hide. A free body's shape and a geometry whose robot file gives it no
colour take the body's colour; a geometry with its own colour is tinted halfway towards it, so that
two robots of one model are told apart.

Force arrows start at the contact point. Each contact force is drawn as two arrows with conical
heads: its normal component (blue) and its friction component (orange), ``force_scale`` metres long
per newton. The default scale draws the bodies' weight m g as DEFAULT_WEIGHT_LENGTH metres, so the
arrows of a standing robot add up to about that length. Contact points are red dots.

The camera frames the bodies at the start: the box bounding them and their shadow on the ground (where
a falling body goes), over the first state shown, or over the whole run for a replay. meshcat's camera
orbits the world's origin, so the viewer's node (``/meshcat``, or the given visualizer's path) is moved
to put that box's centre there.

The page (a replay's saved HTML, and the live page) carries an overlay of gaussim's own: the simulated
time, play/pause and a time slider driving meshcat's animation, the arrows' scale in N per m and each
body's colour. A page opened at ``replay.html#t=0.5`` stops at t = 0.5 s.

meshcat is imported here only, when a viewer is made. A live viewer starts its own meshcat server
(``viewer_server.py``) with both sockets on 127.0.0.1, which exits with the process that started it; a
viewer made for a page only (``live=False``) keeps the scene in-process and starts no server; a viewer
given a ``meshcat.Visualizer`` draws into it and leaves it open.
"""

from __future__ import annotations

import atexit
import colorsys
import contextlib
import io
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Callable, Sequence
from html import escape
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .constraints import ContactForce
from .exceptions import GaussimError, InvalidOptions
from .files import write_atomic
from .report import StepReport
from .runlog import RunLog
from .scene import Box, Ground, Scene, Sphere
from .state import State
from .world import BodyLayout

# The bodies' weight is drawn this long by default [m].
DEFAULT_WEIGHT_LENGTH = 0.25
NORMAL_COLOR, FRICTION_COLOR, POINT_COLOR = 0x1F77B4, 0xFF7F0E, 0xD62728
GROUND_COLOR, OBSTACLE_COLOR = 0xB0B0B0, 0x8FBC8F
ARROW_RADIUS = 0.004  # [m]
# An arrow's conical head [m]; an arrow shorter than twice HEAD_LENGTH has a head half its length.
HEAD_LENGTH, HEAD_RADIUS = 0.03, 0.011
POINT_RADIUS = 0.008  # [m]
GROUND_SIZE = 4.0  # side of the drawn ground square [m]
# A replay holds at most this many frames (each is a full set of transforms in the page).
MAX_FRAMES = 100_000
# Arrows shorter than this are hidden [m].
MIN_ARROW = 1e-4
# Node names: the bodies (one folder per body), the world and the contacts (one folder per contact).
BODIES, WORLD, CONTACTS = "bodies", "world", "contacts"
# A geometry with its own colour is drawn this far from it towards its body's colour.
TINT = 0.5
# The k-th tree of a body past its first (a robot file of several free links) turns its hue by k times
# this (of a full turn), so that each is told apart.
TREE_HUE = 0.15
# meshcat's camera: vertical field of view [deg]; the framed bodies' bounding sphere fills this share
# of it; the smallest framed radius [m]; the direction from the bodies to the camera (world frame).
CAMERA_FOV, FRAME_FILL, MIN_FRAMED_RADIUS = 75.0, 0.85, 0.1
CAMERA_DIRECTION = np.array([0.75, -0.5, 0.45]) / np.linalg.norm([0.75, -0.5, 0.45])
# A replay is framed over at most this many of its states.
FRAMED_STATES = 50
# The node whose property "simulated_time" the live page's overlay shows [s].
CLOCK = "/Clock"


# gaussim's overlay of a page: the legend (top left) and the time bar (bottom), which drives meshcat's
# animator (``viewer.animator``: play, pause, seek, time) once an animation is loaded. In a live page
# before that, the bar shows the simulated time that Viewer.show sets on the CLOCK node.
_OVERLAY = """
<style>
  #gaussim-legend, #gaussim-bar { position: fixed; z-index: 10; font: 13px sans-serif; color: #111;
    background: rgba(255, 255, 255, 0.85); border-radius: 4px; padding: 4px 8px; }
  #gaussim-legend { left: 8px; top: 8px; max-width: 40vw; }
  #gaussim-legend i { display: inline-block; width: 10px; height: 10px; margin: 0 4px 0 8px; }
  #gaussim-legend b { display: inline-block; width: 24px; height: 3px; margin: 0 4px 3px 8px; }
  #gaussim-bar { left: 8px; right: 8px; bottom: 8px; display: flex; align-items: center; gap: 8px; }
  #gaussim-bar input { flex: 1; }
  #gaussim-play { width: 70px; }
  #gaussim-time { min-width: 110px; font-variant-numeric: tabular-nums; }
  #gaussim-stopped { color: #b00020; }
</style>
<div id="gaussim-legend">force arrows: 1 m = @SCALE@ N
  <b style="background:@NORMAL@"></b>normal <b style="background:@FRICTION@"></b>friction<br>@BODIES@
  @STOPPED@</div>
<div id="gaussim-bar"><button id="gaussim-play">play</button>
  <input id="gaussim-scrub" type="range" min="0" max="0" step="any" value="0" disabled>
  <span id="gaussim-time">t = 0.000 s</span></div>
<script>
(function () {
  var config = @CONFIG@;
  var play = document.getElementById("gaussim-play"), scrub = document.getElementById("gaussim-scrub");
  var clock = document.getElementById("gaussim-time");
  var wanted = /[#&]t=([-+0-9.eE]+)/.exec(location.hash);  // replay.html#t=0.5 stops there
  var seekTo = wanted ? parseFloat(wanted[1]) : null;
  function seek(animator, time) {
    animator.pause();
    animator.seek(time);
    animator.display_progress(time);
  }
  play.onclick = function () {
    var animator = viewer.animator;
    if (animator.duration === 0) return;
    if (animator.playing) { animator.pause(); return; }
    if (animator.time >= animator.duration - 1e-9) animator.reset();
    animator.actions.forEach(function (action) { action.paused = false; });
    animator.play();
  };
  scrub.oninput = function () { seek(viewer.animator, parseFloat(scrub.value)); };
  setInterval(function () {
    var animator = viewer.animator;
    if (animator.duration > 0) {
      if (scrub.disabled) { scrub.disabled = false; scrub.max = animator.duration; }
      if (seekTo !== null) {
        seek(animator, Math.min(animator.duration, Math.max(0, (seekTo - config.t0) / config.speed)));
        seekTo = null;
      }
      scrub.value = animator.time;
      clock.textContent = "t = " + (config.t0 + animator.time * config.speed).toFixed(3) + " s";
      play.textContent = animator.playing ? "pause" : "play";
    } else if (config.live) {
      var node = viewer.scene_tree.children["Clock"];
      var t = node ? node.object.simulated_time : undefined;
      if (t !== undefined) clock.textContent = "t = " + t.toFixed(3) + " s (live)";
      play.disabled = true;
    }
    if (animator.duration > 0) play.disabled = false;
  }, 50);
})();
</script>
"""


class Viewer:
    """A meshcat view of a scene. Attach it to a run (:meth:`show` each frame) or replay a log.

    Args:
        scene: the scene to draw (bodies, ground, obstacles).
        force_scale: arrow length per force [m/N]; default: the bodies' weight is DEFAULT_WEIGHT_LENGTH.
        zmq_url: an already running meshcat server; by default a new one is started on 127.0.0.1.
        live: False for a viewer that only makes pages (:meth:`static_html`): no server, no socket.
        meshcat: a ``meshcat.Visualizer`` already open: the scene is drawn into it (under its path), and
            :meth:`close` leaves it open.

    In Jupyter, ``viewer.meshcat.jupyter_cell()`` embeds the live view.
    """

    def __init__(
        self,
        scene: Scene,
        *,
        force_scale: float | None = None,
        zmq_url: str | None = None,
        live: bool = True,
        meshcat: Any = None,
    ) -> None:
        from meshcat import Visualizer

        robot = scene.robot
        self.scene = scene
        weight = pin.computeTotalMass(robot.model) * float(np.linalg.norm(scene.gravity))
        self.force_scale = (
            force_scale if force_scale is not None else DEFAULT_WEIGHT_LENGTH / max(weight, 1e-9)
        )
        if not (np.isfinite(self.force_scale) and self.force_scale > 0):
            raise GaussimError(f"force_scale must be a positive number, got {force_scale}")
        self.model = robot.model
        self.visual = _visual_model(robot.visual_model, robot.collision_model)
        self.data = robot.model.createData()
        self.visual_data = pin.GeometryData(self.visual)
        self._owned = meshcat is None  # a visualizer given by the user stays open
        self._replay_clock = (0.0, 1.0)  # the replay's first simulated time [s] and its speed
        self._stopped: str | None = None  # why the replayed run ended early (None: it ran to its end)
        if meshcat is not None:
            if not isinstance(meshcat, Visualizer):
                raise GaussimError(f"meshcat must be a meshcat.Visualizer, got {type(meshcat).__name__}")
            self.meshcat = meshcat
        elif not live:
            self.meshcat = Visualizer(window=_PageWindow())
        else:
            server = None if zmq_url is not None else _start_server(self._overlay(live=True))
            try:
                # meshcat prints its URL; we print it when useful
                with contextlib.redirect_stdout(io.StringIO()):
                    self.meshcat = Visualizer(zmq_url=zmq_url or server[1])  # type: ignore[index]
            except BaseException:
                if server is not None:
                    _stop(server[0])
                raise
            self.meshcat.window.server_proc = server[0] if server else None
        self._contacts: set[str] = set()
        self._aimed = False
        self._nodes = self._draw_bodies()
        self._draw_world()

    @property
    def url(self) -> str:
        """The page of the live view (http://127.0.0.1:PORT/static/)."""
        return str(self.meshcat.url())

    # -- live ------------------------------------------------------------------------------------------

    def show(self, q: np.ndarray, contacts: Sequence[ContactForce] = (), t: float | None = None) -> None:
        """Draw the bodies at the world's configuration q (nq,) and the given contact forces (others are
        hidden); the live page shows the simulated time t [s] when given. The first call frames the
        camera on the bodies."""
        self._aim([q])
        for node, placement in self._placements(q):
            self.meshcat[node].set_transform(placement)
        if t is not None:
            self.meshcat[CLOCK].set_property("simulated_time", float(t))
        shown = set()
        for c in contacts:
            node = self._contact_node(c.name)
            for part, vector in zip(("normal", "friction"), _components(c.force, c.normal)):
                transforms, visible = _arrow(c.point, vector, self.force_scale)
                arrow = self.meshcat[node][part]
                arrow.set_property("visible", visible)
                if visible:
                    for child, (transform, scale) in transforms.items():
                        (arrow[child] if child else arrow).set_transform(transform @ np.diag([*scale, 1.0]))
            self.meshcat[node]["point"].set_transform(pin.SE3(np.eye(3), c.point).homogeneous)
            self.meshcat[node].set_property("visible", True)
            shown.add(c.name)
        for name in self._contacts - shown:
            self.meshcat[_node_name(name)].set_property("visible", False)

    # -- replay ----------------------------------------------------------------------------------------

    def replay(self, log: RunLog, fps: float = 30.0, speed: float = 1.0) -> None:
        """Load the run as a meshcat animation (bodies' motion and force arrows) at ``fps`` frames per
        second of wall time, ``speed`` times real time; the page plays it and has its controls."""
        from meshcat.animation import Animation

        if not (fps > 0 and speed > 0):
            raise GaussimError(f"fps and speed must be > 0, got {fps} and {speed}")
        t = log.t
        count = (t[-1] - t[0]) * fps / speed
        if not count <= MAX_FRAMES:
            raise InvalidOptions(
                "fps", f"{fps:g} frames/s at speed {speed:g} make {count:.3g} frames, more than {MAX_FRAMES}"
            )
        animation = Animation(default_framerate=fps)
        self._replay_clock = (float(t[0]), float(speed))
        # a page of a killed or failed run must not pass for the whole run
        self._stopped = None if log.complete else f"the run did not finish: {log.reason}"
        self._aim(log.q[:: max(1, len(log.q) // FRAMED_STATES)])
        frames = np.arange(0.0, t[-1] - t[0] + 1e-12, speed / fps)
        states = np.minimum(np.searchsorted(t - t[0], frames - 1e-12), len(t) - 1)
        contacts = log.contact_arrays()
        names = log.contact_names
        for name in names:
            self._contact_node(name)
        # the contacts of state k (k >= 1) are those of the step that led to it, step k - 1
        first = np.searchsorted(contacts["step"], states - 1, side="left")
        last = np.searchsorted(contacts["step"], states - 1, side="right")
        for frame, (k, lo, hi) in enumerate(zip(states.tolist(), first.tolist(), last.tolist())):
            with animation.at_frame(self.meshcat, frame) as f:
                for node, placement in self._placements(log.q[k]):
                    f[node].set_transform(placement)
                visible = set()
                for row in range(lo, hi) if k > 0 else ():
                    name = names[contacts["id"][row]]
                    node = _node_name(name)
                    point, normal, force = (
                        contacts["point"][row],
                        contacts["normal"][row],
                        contacts["force"][row],
                    )
                    for part, vector in zip(("normal", "friction"), _components(force, normal)):
                        transforms, shown = _arrow(point, vector, self.force_scale)
                        for child, (transform, scale) in transforms.items():
                            # an animation's transform keeps no scale: it is a property of its own
                            arrow = f[node][part][child] if child else f[node][part]
                            arrow.set_transform(transform)
                            arrow.set_property("scale", "vector3", list(scale))
                        f[node][part].set_property("visible", "boolean", shown)
                    f[node]["point"].set_transform(pin.SE3(np.eye(3), point).homogeneous)
                    visible.add(name)
                for name in names:
                    f[_node_name(name)].set_property("visible", "boolean", name in visible)
        self.meshcat.set_animation(animation, play=True, repetitions=1)

    def static_html(self) -> str:
        """A self-contained page of the current view and animation (no server, no network needed), with
        gaussim's overlay: the time, play/pause and a time slider, the arrows' scale, the bodies'
        colours."""
        page = str(self.meshcat.static_html())
        marker = '<script id="embedded-json">'
        if marker not in page:
            raise GaussimError("this meshcat version's page has no place for gaussim's overlay")
        return page.replace(marker, self._overlay(live=False) + marker, 1)

    def save_html(self, path: str | Path) -> Path:
        """Write :meth:`static_html` to ``path`` atomically (a failed write leaves any previous page)."""
        return write_atomic(path, self.static_html().encode())

    def close(self) -> None:
        """Stop the meshcat server this viewer started (an external one, given by zmq_url, keeps running;
        a visualizer given as ``meshcat`` stays open)."""
        window = self.meshcat.window
        if isinstance(window, _PageWindow) or not self._owned:
            return
        window.zmq_socket.close(linger=0)
        if window.server_proc is not None:
            _stop(window.server_proc)

    def __enter__(self) -> Viewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- drawing ---------------------------------------------------------------------------------------

    def _aim(self, configurations: Sequence[np.ndarray] | np.ndarray) -> None:
        """Point the camera once at the box bounding the bodies over these configurations (nq,) and
        their shadow on the ground, from the distance at which it fills FRAME_FILL of the view."""
        if self._aimed:
            return
        self._aimed = True
        low, high = self.bounds(configurations)
        corners = np.array([[(low, high)[(k >> i) & 1][i] for i in range(3)] for k in range(8)])
        grounds = [o for o in self.scene.obstacles if isinstance(o, Ground)]
        for ground in grounds:  # where the bodies fall to
            n = np.asarray(ground.normal, dtype=float)
            corners = np.vstack([corners, corners - np.outer(corners @ n - ground.height, n)])
        low, high = corners.min(axis=0), corners.max(axis=0)
        center, radius = (low + high) / 2, max(MIN_FRAMED_RADIUS, float(np.linalg.norm(high - low)) / 2)
        distance = radius / (FRAME_FILL * math.sin(math.radians(CAMERA_FOV) / 2))
        # meshcat's camera orbits and looks at the world's origin: the scene moves to put the bodies there
        self.meshcat.set_transform(pin.SE3(np.eye(3), -center).homogeneous)
        x, y, z = distance * CAMERA_DIRECTION
        # the camera node is y-up (meshcat turns it by +90 deg about x): world (x, y, z) is (x, z, -y) there
        self.meshcat["/Cameras/default/rotated/<object>"].set_property("position", [x, z, -y])
        self.meshcat["/Grid"].set_property("visible", False)
        self.meshcat["/Axes"].set_property("visible", False)

    def bounds(self, configurations: Sequence[np.ndarray] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The corners (low, high), each (3,) [m], of the axis-aligned box that holds every drawn
        geometry's bounding sphere in each of these configurations (nq,)."""
        spheres = []
        for g in range(self.visual.ngeoms):
            geometry = self.visual.geometryObjects[g].geometry
            geometry.computeLocalAABB()
            spheres.append((np.asarray(geometry.aabb_center), float(geometry.aabb_radius)))
        low, high = np.full(3, np.inf), np.full(3, -np.inf)
        for q in configurations:
            pin.forwardKinematics(self.model, self.data, q)
            pin.updateGeometryPlacements(self.model, self.data, self.visual, self.visual_data)
            for placement, (center, radius) in zip(self.visual_data.oMg, spheres):
                point = placement.act(center)
                low, high = np.minimum(low, point - radius), np.maximum(high, point + radius)
        return low, high

    def _overlay(self, live: bool) -> str:
        """gaussim's overlay of the page: the time and the animation's controls, the arrows' scale,
        the bodies' colours and, for a run that stopped early, when and why (HTML)."""
        bodies = "".join(
            f'<span><i style="background:#{_hex(b.color):06x}"></i>{escape(b.name)}</span>'
            for b in self.scene.world.bodies.values()
        )
        config = {"t0": self._replay_clock[0], "speed": self._replay_clock[1], "live": live}
        stopped = (
            "" if self._stopped is None else f'<br><span id="gaussim-stopped">{escape(self._stopped)}</span>'
        )

        return (
            _OVERLAY.replace("@CONFIG@", json.dumps(config))
            .replace("@NORMAL@", f"#{NORMAL_COLOR:06x}")
            .replace("@FRICTION@", f"#{FRICTION_COLOR:06x}")
            .replace("@SCALE@", f"{1 / self.force_scale:.3g}")
            .replace("@BODIES@", bodies)
            .replace("@STOPPED@", stopped)
        )

    def _placements(self, q: np.ndarray) -> list[tuple[str, np.ndarray]]:
        """Each drawn geometry's node and its placement (4, 4) at configuration q, its mesh scale
        included."""
        pin.forwardKinematics(self.model, self.data, q)
        pin.updateGeometryPlacements(self.model, self.data, self.visual, self.visual_data)
        return [
            (
                node,
                self.visual_data.oMg[g].homogeneous @ np.diag([*self.visual.geometryObjects[g].meshScale, 1]),
            )
            for g, node in self._nodes
        ]

    def _draw_bodies(self) -> list[tuple[int, str]]:
        """Draw every visual geometry under its body's node, in its colour; the (geometry index, node)
        of those drawn (a geometry meshcat cannot show is reported in a warning)."""
        world = self.scene.world
        nodes, skipped = [], []
        for g, obj in enumerate(self.visual.geometryObjects):
            # a one-body world's names carry no prefix; a world of several names each "body/geometry"
            body = (
                next(iter(world.bodies.values())) if len(world) == 1 else world.body(obj.name.split("/")[0])
            )
            shape = _shape(obj)
            if shape is None:
                skipped.append(obj.name)
                continue
            node = f"{BODIES}/{body.name}/{obj.name.removeprefix(body.prefix)}"
            rgba = _color(body, obj, _tree(self.model, body, obj.parentJoint))
            self.meshcat[node].set_object(shape, _material(_hex(rgba), float(rgba[3]), phong=True))
            nodes.append((g, node))
        if skipped:
            warnings.warn(f"meshcat cannot draw these geometries: {', '.join(skipped)}", stacklevel=3)
        return nodes

    def _draw_world(self) -> None:
        import meshcat.geometry as mg

        for obstacle in self.scene.obstacles:
            node = self.meshcat[WORLD][obstacle.name]
            if isinstance(obstacle, Ground):
                thickness = 0.01
                node.set_object(mg.Box([GROUND_SIZE, GROUND_SIZE, thickness]), _material(GROUND_COLOR, 0.6))
                n = np.asarray(obstacle.normal)
                rotation = _frame_along(n, axis=2)
                node.set_transform(pin.SE3(rotation, n * (obstacle.height - thickness / 2)).homogeneous)
            elif isinstance(obstacle, Box):
                node.set_object(mg.Box(list(obstacle.size)), _material(OBSTACLE_COLOR, 0.8))
                node.set_transform(obstacle.placement().homogeneous)
            elif isinstance(obstacle, Sphere):
                node.set_object(mg.Sphere(obstacle.radius), _material(OBSTACLE_COLOR, 0.8))
                node.set_transform(obstacle.placement().homogeneous)

    def _contact_node(self, name: str) -> str:
        """The folder of a contact's arrows and point, created on first use."""
        node = _node_name(name)
        if name not in self._contacts:
            import meshcat.geometry as mg

            for part, color in (("normal", NORMAL_COLOR), ("friction", FRICTION_COLOR)):
                # along y: a unit cylinder (the shaft) and a cone (the head), placed by _arrow
                self.meshcat[node][part]["shaft"].set_object(mg.Cylinder(1.0, ARROW_RADIUS), _material(color))
                head = mg.Cylinder(HEAD_LENGTH, radiusTop=0.0, radiusBottom=HEAD_RADIUS)
                self.meshcat[node][part]["head"].set_object(head, _material(color))
            self.meshcat[node]["point"].set_object(mg.Sphere(POINT_RADIUS), _material(POINT_COLOR))
            self._contacts.add(name)
        return node


def _start_server(overlay: str) -> tuple[subprocess.Popen, str]:
    """Start ``viewer_server.py`` (both sockets on 127.0.0.1, gone when this process is; its page carries
    the ``overlay`` HTML); the process and its ZMQ address."""
    errors = tempfile.TemporaryFile()
    server = subprocess.Popen(
        [sys.executable, "-u", str(Path(__file__).with_name("viewer_server.py")), str(os.getpid())],
        stdout=subprocess.PIPE,
        stderr=errors,
        stdin=subprocess.PIPE,
        start_new_session=True,  # a Ctrl-C in the terminal is ours to handle: we stop the server after it
    )
    assert server.stdin is not None
    with contextlib.suppress(BrokenPipeError):  # a server that failed to start says why below
        server.stdin.write(overlay.encode())
        server.stdin.close()
    atexit.register(_stop, server)
    assert server.stdout is not None
    line = server.stdout.readline().decode()
    if not line.startswith("zmq_url="):
        server.wait()
        errors.seek(0)
        message = errors.read().decode(errors="replace").strip()[-2000:]
        raise GaussimError(f"the meshcat server did not start (exit code {server.returncode}): {message}")
    return server, line.removeprefix("zmq_url=").strip()


def _stop(server: subprocess.Popen) -> None:
    if server.poll() is None:
        server.terminate()
        try:
            server.wait(timeout=5)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()
    if server.stdout is not None:
        server.stdout.close()


class _PageWindow:
    """A meshcat window with no server: the scene tree is kept in-process by meshcat's own bridge code
    (its ``handle_zmq``, with no socket), so that its page (``get_scene``) is the one a server makes."""

    server_proc = None
    web_url = ""

    def __init__(self) -> None:
        from meshcat.servers.tree import SceneTree
        from meshcat.servers.zmqserver import ZMQWebSocketBridge

        self._reply = _Reply()
        self._bridge = ZMQWebSocketBridge.__new__(ZMQWebSocketBridge)  # no sockets, no web server
        self._bridge.tree, self._bridge.websocket_pool = SceneTree(), set()
        self._bridge.zmq_socket = self._reply

    def send(self, command: Any) -> None:
        import umsgpack

        data = command.lower()
        self._bridge.handle_zmq([data["type"].encode(), data["path"].encode(), umsgpack.packb(data)])

    def get_scene(self) -> str:
        self._bridge.handle_zmq([b"get_scene"])
        return self._reply.data.decode()


class _Reply:
    """Where meshcat's bridge sends its answer, in place of its ZMQ socket."""

    data = b""

    def send(self, data: bytes) -> None:
        self.data = data


def _node_name(contact: str) -> str:
    return f"{CONTACTS}/{contact.replace('/', ':')}"  # meshcat paths use '/'


def _components(force: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    normal_part = float(force @ normal) * normal
    return normal_part, force - normal_part


def _arrow(
    point: np.ndarray, vector: np.ndarray, scale: float
) -> tuple[dict[str, tuple[np.ndarray, tuple[float, float, float]]], bool]:
    """The placements (4, 4) and scales (3,) of an arrow scale * |vector| [m] long from ``point`` along
    ``vector``, by node ("" the arrow, whose y axis runs along the vector; "shaft" and "head" in it),
    and whether it is shown (at least MIN_ARROW long)."""
    norm = float(np.linalg.norm(vector))
    rotation = _frame_along(vector / norm, axis=1) if norm > 0 else np.eye(3)
    length = scale * norm
    head = max(min(HEAD_LENGTH, length / 2), MIN_ARROW)
    shaft = max(length - head, MIN_ARROW)
    return {
        "": (pin.SE3(rotation, np.asarray(point, dtype=float)).homogeneous, (1.0, 1.0, 1.0)),
        "shaft": (_along_y(shaft / 2), (1.0, shaft, 1.0)),
        "head": (_along_y(length - head / 2), (head / HEAD_LENGTH,) * 3),
    }, length > MIN_ARROW


def _along_y(y: float) -> np.ndarray:
    """The translation (4, 4) by y [m] along y."""
    return pin.SE3(np.eye(3), np.array([0.0, y, 0.0])).homogeneous


def _frame_along(direction: np.ndarray, axis: int) -> np.ndarray:
    """A rotation whose column ``axis`` is the unit vector ``direction`` (the next two columns follow
    cyclically, so that the frame is right-handed)."""
    helper = np.eye(3)[int(np.argmin(np.abs(direction)))]
    a = np.cross(direction, helper)
    a /= np.linalg.norm(a)
    rotation = np.empty((3, 3))
    rotation[:, axis], rotation[:, (axis + 1) % 3], rotation[:, (axis + 2) % 3] = (
        direction,
        a,
        np.cross(direction, a),
    )
    return rotation


def _material(color: int, opacity: float = 1.0, phong: bool = False) -> Any:
    import meshcat.geometry as mg

    kind = mg.MeshPhongMaterial if phong else mg.MeshLambertMaterial
    return kind(color=color, opacity=opacity, transparent=opacity < 1.0)


def _hex(rgba: Sequence[float] | np.ndarray) -> int:
    """An RGB colour of channels in [0, 1] as the integer 0xRRGGBB."""
    red, green, blue = (int(round(255 * float(np.clip(c, 0.0, 1.0)))) for c in rgba[:3])
    return red << 16 | green << 8 | blue


def _tree(model: pin.Model, body: BodyLayout, joint: int) -> int:
    """Which of the body's kinematic trees (0, 1, ...: one per joint on the world, as the three free
    boxes of one robot file) holds this joint (0 for the world itself)."""
    roots = [j for j in body.joints if model.parents[j] == 0]
    while joint and model.parents[joint] != 0:
        joint = model.parents[joint]
    return roots.index(joint) if joint in roots else 0


def _color(body: BodyLayout, obj: pin.GeometryObject, tree: int = 0) -> np.ndarray:
    """A geometry's RGBA (4,): its body's colour, its hue turned by TREE_HUE per tree of the body past
    the first, or its own colour (given by its robot file) tinted by TINT towards that."""
    color = np.asarray(body.color, dtype=float)
    if tree > 0:
        hue, saturation, value = colorsys.rgb_to_hsv(*color[:3])
        color[:3] = colorsys.hsv_to_rgb((hue + tree * TREE_HUE) % 1.0, saturation, value)
    if body.free or not obj.overrideMaterial:
        return color
    own = np.asarray(obj.meshColor, dtype=float)
    return np.append((1 - TINT) * own[:3] + TINT * color[:3], own[3] * color[3])


def _shape(obj: pin.GeometryObject) -> Any:
    """The meshcat geometry of a Pinocchio geometry object, or None: a primitive (box, sphere,
    cylinder, capsule, cone) or a convex hull as coal holds it, a mesh from its file (STL, OBJ, DAE:
    the shape only; the colour is the body's), or a triangle mesh without a file."""
    import coal
    import meshcat.geometry as mg
    from pinocchio.visualize.meshcat_visualizer import loadMesh, loadPrimitive

    if isinstance(obj.geometry, coal.ShapeBase):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # an unsupported shape is reported by the caller
            return loadPrimitive(obj)
    files = {".stl": mg.StlMeshGeometry, ".obj": mg.ObjMeshGeometry, ".dae": mg.DaeMeshGeometry}
    kind = files.get(Path(obj.meshPath).suffix.lower())
    if kind is not None and Path(obj.meshPath).is_file():
        return kind.from_file(obj.meshPath)
    if isinstance(obj.geometry, coal.BVHModelBase):
        return loadMesh(obj.geometry)
    return None


def _visual_model(visual: pin.GeometryModel, collision: pin.GeometryModel) -> pin.GeometryModel:
    """The visual geometry, or the collision geometry when visual meshes are missing (with a warning
    naming the files)."""
    import coal

    missing = [
        f"{g.name}: {g.meshPath}"
        for g in visual.geometryObjects
        # a primitive's meshPath is its kind ("BOX"), not a file
        if g.meshPath and not isinstance(g.geometry, coal.ShapeBase) and not Path(g.meshPath).is_file()
    ]
    if not visual.ngeoms or missing:
        if missing:
            warnings.warn(
                "missing visual meshes, showing the collision geometry instead: " + "; ".join(missing),
                stacklevel=3,
            )
        return collision
    return visual


def follow(viewer: Viewer, speed: float = 1.0, fps: float = 30.0) -> Callable[[State, StepReport], None]:
    """An observer for :func:`gaussim.runner.run` that shows the run live at ``speed`` times real time
    (frames every 1/fps s of wall time; the run waits when it is ahead). The clock starts at the first
    step (after the kernels compile), and a run that falls behind (a slow step) goes on from where it
    is at real time, never faster to catch up."""
    if not (fps > 0 and speed > 0):
        raise GaussimError(f"fps and speed must be > 0, got {fps} and {speed}")
    start = last = -np.inf  # the wall time at which simulated time 0 is shown [s]; the last frame's t

    def observe(state: State, report: StepReport) -> None:
        nonlocal start, last
        if state.t - last < speed / fps:
            return
        last = state.t
        now = time.perf_counter()
        ahead = state.t / speed - (now - start)
        if ahead > 0:
            time.sleep(ahead)
        elif ahead < -1 / fps:  # behind: the clock restarts at this frame
            start = now - state.t / speed
        viewer.show(state.q, report.contacts, state.t)

    return observe


def screenshot(
    page: str | Path,
    png: str | Path,
    size: tuple[int, int] = (960, 640),
    wait_ms: int = 4000,
    at: float | None = None,
) -> Path:
    """Render a page with headless Chromium (Debian's ``chromium``) into a PNG, a replay stopped at the
    simulated time ``at`` [s] when given; raises GaussimError when Chromium is missing or fails."""
    png = Path(png).resolve()
    png.parent.mkdir(parents=True, exist_ok=True)
    png.unlink(missing_ok=True)
    _chromium(
        page,
        f"--screenshot={png}",
        f"--window-size={size[0]},{size[1]}",
        f"--timeout={wait_ms}",
        fragment=_at(at),
    )
    if not png.is_file():
        raise GaussimError(f"chromium wrote no screenshot of {page}")
    return png


def page_dom(html: str | Path, wait_ms: int = 4000, at: float | None = None) -> str:
    """The DOM of a page after it ran for ``wait_ms`` (headless Chromium), a replay stopped at the
    simulated time ``at`` [s] when given, as HTML text."""
    return _chromium(html, f"--timeout={wait_ms}", "--dump-dom", fragment=_at(at)).stdout


def page_errors(html: str | Path, wait_ms: int = 4000) -> list[str]:
    """The JavaScript errors a page raised (uncaught, as its console shows them) while headless Chromium
    ran it for ``wait_ms``: a page that does not load says why here, not in its pixels."""
    logged = _chromium(html, f"--timeout={wait_ms}", "--dump-dom", "--enable-logging=stderr", "--v=0")
    return _UNCAUGHT.findall(logged.stderr)


def _at(at: float | None) -> str:
    """The page's URL fragment that stops a replay at the simulated time ``at`` [s]."""
    return "" if at is None else f"#t={at:.6g}"


# an uncaught JavaScript error in Chromium's log (--enable-logging=stderr): its console's message
_UNCAUGHT = re.compile(r':CONSOLE[^\]]*\] "(Uncaught [^\n]*)", source: ')


def _chromium(
    html: str | Path, *options: str, timeout: float = 120.0, fragment: str = ""
) -> subprocess.CompletedProcess[str]:
    """Run headless Chromium on a page in a fresh profile; the finished process (its output as text).
    (Measured with Chromium 150: ``--virtual-time-budget`` hangs on meshcat's animated page 2 runs in 5,
    and a Chromium started in a new session hangs too; ``--timeout`` in our session has not.)"""
    import shutil

    binary = next(
        (p for n in ("chromium", "chromium-browser", "google-chrome") if (p := shutil.which(n))), None
    )
    if binary is None:
        raise GaussimError("headless rendering needs Chromium: apt-get install chromium")
    with tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as profile:
        # software WebGL: no GPU on a server
        command = [binary, "--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader"]
        command += [
            "--use-angle=swiftshader",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            f"--user-data-dir={profile}",
            *options,
            Path(html).resolve().as_uri() + fragment,
        ]
        try:
            result = subprocess.run(command, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired as error:
            raise GaussimError(f"chromium did not finish rendering {html} within {timeout:.0f} s") from error
    if result.returncode != 0:
        raise GaussimError(f"chromium could not render {html}: {result.stderr.strip()[-500:]}")
    return result

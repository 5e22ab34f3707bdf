"""Browser viewer (meshcat): the bodies, the world, the contact points and the force arrows, live or
as a self-contained replay page.

Each body is drawn in its colour (``BodyLayout.color``) under its own node, ``bodies/<body>``, which
the page's controls show or hide. A free body's shape and a geometry whose robot file gives it no
colour take the body's colour; a geometry with its own colour is tinted halfway towards it, so that
two robots of one model are told apart.

Force arrows start at the contact point. Each contact force is drawn as two arrows: its normal
component (blue) and its friction component (orange), ``force_scale`` metres long per newton. The
default scale draws the bodies' weight m g as DEFAULT_WEIGHT_LENGTH metres, so the arrows of a
standing robot add up to about that length. Contact points are red dots.

meshcat is imported here only, when a viewer is made. A live viewer starts its own meshcat server
(``viewer_server.py``) with both sockets on 127.0.0.1, which exits with the process that started it; a
viewer made for a page only (``live=False``) keeps the scene in-process and starts no server.
"""

from __future__ import annotations

import atexit
import contextlib
import io
import os
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Callable, Sequence
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


class Viewer:
    """A meshcat view of a scene. Attach it to a run (:meth:`show` each frame) or replay a log.

    Args:
        scene: the scene to draw (bodies, ground, obstacles).
        force_scale: arrow length per force [m/N]; default: the bodies' weight is DEFAULT_WEIGHT_LENGTH.
        zmq_url: an already running meshcat server; by default a new one is started on 127.0.0.1.
        live: False for a viewer that only makes pages (:meth:`static_html`): no server, no socket.

    In Jupyter, ``viewer.meshcat.jupyter_cell()`` embeds the live view.
    """

    def __init__(
        self,
        scene: Scene,
        *,
        force_scale: float | None = None,
        zmq_url: str | None = None,
        live: bool = True,
    ) -> None:
        import meshcat

        robot = scene.robot
        self.scene = scene
        if not live:
            self.meshcat = meshcat.Visualizer(window=_PageWindow())
        else:
            server = None if zmq_url is not None else _start_server()
            try:
                # meshcat prints its URL; we print it when useful
                with contextlib.redirect_stdout(io.StringIO()):
                    self.meshcat = meshcat.Visualizer(zmq_url=zmq_url or server[1])  # type: ignore[index]
            except BaseException:
                if server is not None:
                    _stop(server[0])
                raise
            self.meshcat.window.server_proc = server[0] if server else None
        self.model = robot.model
        self.visual = _visual_model(robot.visual_model, robot.collision_model)
        self.data = robot.model.createData()
        self.visual_data = pin.GeometryData(self.visual)
        weight = pin.computeTotalMass(robot.model) * float(np.linalg.norm(scene.gravity))
        self.force_scale = (
            force_scale if force_scale is not None else DEFAULT_WEIGHT_LENGTH / max(weight, 1e-9)
        )
        if not (np.isfinite(self.force_scale) and self.force_scale > 0):
            raise GaussimError(f"force_scale must be a positive number, got {force_scale}")
        self._contacts: set[str] = set()
        self._aimed = False
        self._nodes = self._draw_bodies()
        self._draw_world()

    @property
    def url(self) -> str:
        """The page of the live view (http://127.0.0.1:PORT/static/)."""
        return str(self.meshcat.url())

    # -- live ------------------------------------------------------------------------------------------

    def show(self, q: np.ndarray, contacts: Sequence[ContactForce] = ()) -> None:
        """Draw the bodies at the world's configuration q (nq,) and the given contact forces (others are
        hidden)."""
        self._aim(q)
        for node, placement in self._placements(q):
            self.meshcat[node].set_transform(placement)
        shown = set()
        for c in contacts:
            node = self._contact_node(c.name)
            for part, vector in zip(("normal", "friction"), _components(c.force, c.normal)):
                pose, length = _arrow(c.point, vector, self.force_scale)
                arrow = self.meshcat[node][part]
                arrow.set_property("visible", length > MIN_ARROW)
                if length > MIN_ARROW:
                    arrow.set_transform(pose @ np.diag([1.0, length, 1.0, 1.0]))
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
        self._aim(log.q[0])
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
                        pose, length = _arrow(point, vector, self.force_scale)
                        f[node][part].set_transform(pose)
                        f[node][part].set_property("scale", "vector3", [1.0, max(length, MIN_ARROW), 1.0])
                        f[node][part].set_property("visible", "boolean", length > MIN_ARROW)
                    f[node]["point"].set_transform(pin.SE3(np.eye(3), point).homogeneous)
                    visible.add(name)
                for name in names:
                    f[_node_name(name)].set_property("visible", "boolean", name in visible)
        self.meshcat.set_animation(animation, play=True, repetitions=1)

    def static_html(self) -> str:
        """A self-contained page of the current view and animation (no server, no network needed)."""
        return str(self.meshcat.static_html())

    def save_html(self, path: str | Path) -> Path:
        """Write :meth:`static_html` to ``path`` atomically (a failed write leaves any previous page)."""
        return write_atomic(path, self.static_html().encode())

    def close(self) -> None:
        """Stop the meshcat server this viewer started (an external one, given by zmq_url, keeps running)."""
        window = self.meshcat.window
        if isinstance(window, _PageWindow):
            return
        window.zmq_socket.close(linger=0)
        if window.server_proc is not None:
            _stop(window.server_proc)

    def __enter__(self) -> Viewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- drawing ---------------------------------------------------------------------------------------

    def _aim(self, q: np.ndarray) -> None:
        """Point the camera at the bodies in configuration q once, from a distance that frames them."""
        if self._aimed:
            return
        self._aimed = True
        model, data = self.model, self.data
        pin.forwardKinematics(model, data, q)
        origins = np.array([placement.translation for placement in data.oMi[1:]])
        center = origins.mean(axis=0)
        distance = 3.0 * max(0.15, float(np.linalg.norm(origins - center, axis=1).max()))
        self.meshcat["/Cameras/default"].set_transform(pin.SE3(np.eye(3), center).homogeneous)
        # the camera node is y-up: in front of the robot (x), to its side and above it
        self.meshcat["/Cameras/default/rotated/<object>"].set_property(
            "position", [0.75 * distance, 0.45 * distance, 0.5 * distance]
        )
        self.meshcat["/Grid"].set_property("visible", False)
        self.meshcat["/Axes"].set_property("visible", False)

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
            rgba = _color(body, obj)
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
                # a unit cylinder along y whose base is at the origin: scaled along y to the arrow's length
                self.meshcat[node][part]["shaft"].set_object(mg.Cylinder(1.0, ARROW_RADIUS), _material(color))
                self.meshcat[node][part]["shaft"].set_transform(
                    pin.SE3(np.eye(3), np.array([0, 0.5, 0])).homogeneous
                )
            self.meshcat[node]["point"].set_object(mg.Sphere(POINT_RADIUS), _material(POINT_COLOR))
            self._contacts.add(name)
        return node


def _start_server() -> tuple[subprocess.Popen, str]:
    """Start ``viewer_server.py`` (both sockets on 127.0.0.1, gone when this process is); the process and
    its ZMQ address."""
    errors = tempfile.TemporaryFile()
    server = subprocess.Popen(
        [sys.executable, "-u", str(Path(__file__).with_name("viewer_server.py")), str(os.getpid())],
        stdout=subprocess.PIPE,
        stderr=errors,
        stdin=subprocess.DEVNULL,
        start_new_session=True,  # a Ctrl-C in the terminal is ours to handle: we stop the server after it
    )
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


def _arrow(point: np.ndarray, vector: np.ndarray, scale: float) -> tuple[np.ndarray, float]:
    """(pose, length): the placement (4, 4) whose y axis runs along ``vector`` from ``point``, and the
    arrow length scale * |vector| [m]."""
    norm = float(np.linalg.norm(vector))
    rotation = _frame_along(vector / norm, axis=1) if norm > 0 else np.eye(3)
    return pin.SE3(rotation, np.asarray(point, dtype=float)).homogeneous, scale * norm


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


def _color(body: BodyLayout, obj: pin.GeometryObject) -> np.ndarray:
    """A geometry's RGBA (4,): its body's colour, or its own (given by its robot file) tinted by TINT
    towards it."""
    color = np.asarray(body.color, dtype=float)
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
    (frames every 1/fps s of wall time; the run waits when it is ahead)."""
    start = time.perf_counter()
    last = -np.inf  # simulated time of the last frame shown

    def observe(state: State, report: StepReport) -> None:
        nonlocal last
        if state.t - last < speed / fps:
            return
        last = state.t
        ahead = state.t / speed - (time.perf_counter() - start)
        if ahead > 0:
            time.sleep(ahead)
        viewer.show(state.q, report.contacts)

    return observe


def screenshot(
    html: str | Path, png: str | Path, size: tuple[int, int] = (960, 640), wait_ms: int = 4000
) -> Path:
    """Render a page with headless Chromium (Debian's ``chromium``) into a PNG; raises GaussimError when
    Chromium is missing or fails."""
    png = Path(png).resolve()
    png.parent.mkdir(parents=True, exist_ok=True)
    png.unlink(missing_ok=True)
    _chromium(html, f"--screenshot={png}", f"--window-size={size[0]},{size[1]}", f"--timeout={wait_ms}")
    if not png.is_file():
        raise GaussimError(f"chromium wrote no screenshot of {html}")
    return png


def page_dom(html: str | Path, wait_ms: int = 4000) -> str:
    """The DOM of a page after it ran for ``wait_ms`` (headless Chromium), as HTML text."""
    return _chromium(html, f"--timeout={wait_ms}", "--dump-dom")


def _chromium(html: str | Path, *options: str, timeout: float = 120.0) -> str:
    """Run headless Chromium on a page in a fresh profile; its standard output. (Measured with Chromium
    150: ``--virtual-time-budget`` hangs on meshcat's animated page 2 runs in 5, and a Chromium started
    in a new session hangs too; ``--timeout`` in our session has not.)"""
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
            f"--user-data-dir={profile}",
            *options,
            Path(html).resolve().as_uri(),
        ]
        try:
            result = subprocess.run(command, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired as error:
            raise GaussimError(f"chromium did not finish rendering {html} within {timeout:.0f} s") from error
    if result.returncode != 0:
        raise GaussimError(f"chromium could not render {html}: {result.stderr.strip()[-500:]}")
    return result.stdout

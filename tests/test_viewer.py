"""The browser viewer as a person sees it: replay pages rendered by headless Chromium, the live
server on 127.0.0.1, the bodies of a world each in its colour, and the fallback for missing meshes."""

from __future__ import annotations

import base64
import html.parser
import re
import urllib.request
import warnings
from pathlib import Path

import numpy as np
import pytest
import umsgpack
from matplotlib.image import imread

import gaussim
from gaussim import Body, FreeBody, pose
from gaussim.viewer import Viewer, _visual_model, page_dom, page_errors, screenshot

# A pixel is drawn differently when one of its channels differs by more than this (of 1).
PIXEL_TOLERANCE = 0.1
# The robot covers at least this fraction of the central region of a replay screenshot.
MIN_ROBOT_FRACTION = 0.01
FEET = ("FL", "FR", "HL", "HR")
# Two body colours far from the sky's blues, the ground's grey and the contact markers' red and orange.
GREEN, MAGENTA = (0.2, 0.8, 0.2, 1.0), (0.8, 0.2, 0.8, 1.0)
# A pixel shows a colour when its chromaticity rgb / (r + g + b) (kept by diffuse shading) is this close.
CHROMA_TOLERANCE = 0.05
# A body shows its colour in at least this fraction of a screenshot (a shaded sphere framed with a box:
# 0.01); a hidden one, in less than NO_BODY_FRACTION.
MIN_BODY_FRACTION, NO_BODY_FRACTION = 0.005, 1e-4
SCENES = Path(__file__).parent.parent / "robots" / "scenes"
# A replay's scene pixels leave this margin to the screenshot's edges [px], and lie above the overlay's
# time bar (the bottom BAR_HEIGHT px); its legend of the bodies' colours is the top LEGEND_HEIGHT px.
FRAME_MARGIN, BAR_HEIGHT, LEGEND_HEIGHT = 2, 50, 60


@pytest.fixture(scope="module")
def pages(solo12_run, tmp_path_factory):
    """The replay page of the run, and the same page with the robot hidden (the background)."""
    log, spec = solo12_run
    folder = tmp_path_factory.mktemp("pages")
    with Viewer(spec.scene) as viewer:
        viewer.replay(log)
        replay = viewer.save_html(folder / "replay.html")
        viewer.meshcat["bodies"].set_property("visible", False)
        viewer.meshcat["contacts"].set_property("visible", False)
        background = viewer.save_html(folder / "background.html")
    return replay, background


def test_replay_page_shows_the_robot(pages, tmp_path):
    replay, background = pages
    for wait_ms in (4000, 12000, 30000):  # software WebGL on a loaded 2-core machine can take longer
        drawn = imread(screenshot(replay, tmp_path / "replay.png", wait_ms=wait_ms))[..., :3]
        empty = imread(screenshot(background, tmp_path / "background.png", wait_ms=wait_ms))[..., :3]
        assert drawn.shape == empty.shape == (640, 960, 3)
        h, w = drawn.shape[:2]
        centre = (slice(h // 4, 3 * h // 4), slice(w // 4, 3 * w // 4))
        changed = np.abs(drawn[centre] - empty[centre]).max(axis=-1) > PIXEL_TOLERANCE
        if changed.mean() > MIN_ROBOT_FRACTION:
            break
    assert changed.mean() > MIN_ROBOT_FRACTION, "the robot was not drawn in the middle of the view"
    outside = np.abs(drawn[:20] - empty[:20]).max(axis=-1) > PIXEL_TOLERANCE  # the sky above the robot
    assert outside.mean() < 0.01


def test_replay_page_scene_tree_holds_the_force_arrows(pages):
    dom = _dom_once_built(pages[0])
    assert "contacts" in dom
    for leg in FEET:
        assert f"{leg}_FOOT_0:ground#0" in dom, f"no force arrows for the {leg} foot in the scene tree"


def test_live_viewer_binds_localhost_and_shuts_down(solo12_run):
    log, spec = solo12_run
    viewer = Viewer(spec.scene)
    server = viewer.meshcat.window.server_proc
    try:
        assert viewer.url.startswith("http://127.0.0.1:")
        with urllib.request.urlopen(viewer.url, timeout=10) as page:
            assert page.status == 200
        import gaussim

        sim = gaussim.Simulator(spec.scene, spec.options)
        state = sim.step(sim.reset(log.q[-1], log.v[-1]))
        viewer.show(state.q, sim.last_step.contacts)  # four feet on the ground
        assert len(sim.last_step.contacts) == 4
    finally:
        viewer.close()
    assert server.poll() is not None, "the meshcat server still runs after close()"


def test_missing_visual_meshes_fall_back_to_collision_geometry(solo12, box):
    visual = solo12.visual_model.copy()
    visual.geometryObjects[0].meshPath = "/nonexistent/base.stl"
    with pytest.warns(UserWarning, match=r"base_link_0: /nonexistent/base.stl"):
        shown = _visual_model(visual, solo12.collision_model)
    assert shown is solo12.collision_model
    assert _visual_model(solo12.visual_model, solo12.collision_model) is solo12.visual_model
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a URDF box's meshPath "BOX" names no file to miss
        assert _visual_model(box.visual_model, box.collision_model) is box.visual_model


def _dom_once_built(page) -> str:
    """The page's DOM once its scripts have built the scene tree: software WebGL on a loaded 2-core
    machine (CI) once took more than the first wait."""
    for wait_ms in (4000, 12000, 30000):
        dom = page_dom(page, wait_ms=wait_ms)
        if "contacts" in dom:
            break
    return dom


@pytest.fixture(scope="module")
def two_bodies(tmp_path_factory):
    """The replay page of a green crate and a magenta ball dropped 1 mm onto the ground (0.1 s), the
    same page with the crate hidden as a user hides it, and the scene."""
    bodies = {
        "crate": Body(FreeBody.box("crate", (0.3, 0.3, 0.2), mass=2.0), color=GREEN),
        "ball": Body(FreeBody.sphere("ball", 0.1, mass=0.5), color=MAGENTA),
    }
    scene = gaussim.Scene(bodies=bodies, ground=gaussim.Ground())
    sim = gaussim.Simulator(scene, gaussim.Options(dt=1e-3))
    state = sim.reset({"crate": pose(z=0.101), "ball": pose(x=0.4, z=0.101)})
    log = gaussim.RunLog(scene.robot.name, "", sim.options)
    log.start(state)
    tau = np.zeros(scene.robot.model.nv)
    for _ in range(100):
        state = sim.step(state)
        log.record(state, tau, sim.last_step)
    log.finish(True)
    folder = tmp_path_factory.mktemp("two_bodies")
    viewer = Viewer(scene, live=False)
    viewer.replay(log)
    replay = viewer.save_html(folder / "replay.html")
    viewer.meshcat["contacts"].set_property("visible", False)  # the arrows cross the bodies
    both = viewer.save_html(folder / "both.html")
    viewer.meshcat["bodies/crate"].set_property("visible", False)
    no_crate = viewer.save_html(folder / "no_crate.html")
    return replay, both, no_crate, scene


def test_replay_page_scene_tree_has_a_folder_per_body(two_bodies):
    """The page's controls hold bodies/crate/box and bodies/ball/sphere (each a toggle) and the
    contact arrows of both bodies on the ground."""
    dom = _dom_once_built(two_bodies[0])
    folders = _folders(dom)
    assert {"Scene/meshcat/bodies/crate/box", "Scene/meshcat/bodies/ball/sphere"} <= folders
    bodies = {f for f in folders if re.fullmatch(r"Scene/meshcat/bodies/[^/]+", f)}
    assert bodies == {"Scene/meshcat/bodies/crate", "Scene/meshcat/bodies/ball"}
    contacts = {f.rsplit("/", 1)[1] for f in folders if f.startswith("Scene/meshcat/contacts/")}
    assert any(c.startswith("crate:box:ground") for c in contacts)
    assert any(c.startswith("ball:sphere:ground") for c in contacts)


def test_replay_page_draws_each_body_in_its_colour(two_bodies, tmp_path):
    """Screenshots: the crate's green and the ball's magenta both appear; hiding the crate's folder
    removes the green and keeps the magenta."""
    _, both, no_crate, _ = two_bodies
    for wait_ms in (4000, 12000, 30000):  # software WebGL on a loaded 2-core machine can take longer
        # below the legend, which shows each body's colour too, and above the time bar
        shown = imread(screenshot(both, tmp_path / "both.png", wait_ms=wait_ms))[LEGEND_HEIGHT:-BAR_HEIGHT]
        hidden = imread(screenshot(no_crate, tmp_path / "no_crate.png", wait_ms=wait_ms))[
            LEGEND_HEIGHT:-BAR_HEIGHT
        ]
        if min(_share(shown, GREEN), _share(shown, MAGENTA), _share(hidden, MAGENTA)) > MIN_BODY_FRACTION:
            break
    assert _share(shown, GREEN) > MIN_BODY_FRACTION, "the crate was not drawn in its colour"
    assert _share(shown, MAGENTA) > MIN_BODY_FRACTION, "the ball was not drawn in its colour"
    assert _share(hidden, MAGENTA) > MIN_BODY_FRACTION, "hiding the crate hid the ball"
    assert _share(hidden, GREEN) < NO_BODY_FRACTION, "the crate is still drawn once hidden"


def test_page_colours_free_shapes_and_tints_a_robot(solo12, tmp_path):
    """In the page's scene data: every free shape (box, sphere, cylinder, capsule, convex mesh) is a
    drawn object in its body's colour (the scene's palette), and Solo-12, whose URDF colours its
    meshes, is drawn in its own grey tinted towards its body's colour."""
    stl = tmp_path / "tetra.stl"
    stl.write_text(_tetrahedron_stl(0.2))
    shapes = {
        "box": FreeBody.box("box", (0.1, 0.2, 0.3), mass=1.0),
        "sphere": FreeBody.sphere("sphere", 0.1, mass=1.0),
        "cylinder": FreeBody.cylinder("cylinder", 0.1, 0.3, mass=1.0),
        "capsule": FreeBody.capsule("capsule", 0.1, 0.3, mass=1.0),
        "mesh": FreeBody.mesh("mesh", str(stl), mass=1.0),
    }
    scene = gaussim.Scene(bodies={"solo": solo12, **shapes})
    page = Viewer(scene, live=False).save_html(tmp_path / "page.html")
    objects = _page_objects(page)
    kinds = {"box": "BoxGeometry", "sphere": "SphereGeometry", "cylinder": "CylinderGeometry"}
    for name in shapes:
        kind, colour = objects[f"/meshcat/bodies/{name}/{name}"]
        assert kind == kinds.get(name, "BufferGeometry"), name  # a capsule and a hull: triangle meshes
        assert colour == _hex(scene.bodies[name].color), name
    colours = {path: colour for path, (_, colour) in objects.items()}
    grey = solo12.visual_model.geometryObjects[0].meshColor
    body_colour = scene.bodies["solo"].color
    solo = {path: c for path, c in colours.items() if path.startswith("/meshcat/bodies/solo/")}
    assert len(solo) == solo12.visual_model.ngeoms
    assert set(solo.values()) == {_hex(0.5 * (np.asarray(grey) + np.asarray(body_colour)))}
    assert len(set(colours.values())) == 1 + len(shapes), "two bodies share a colour"


def _share(image: np.ndarray, rgba) -> float:
    """The fraction of an image's lit pixels (H, W, 3 or 4) whose chromaticity is that of rgba."""
    rgb = image[..., :3]
    total = rgb.sum(axis=-1)
    chroma = rgb / np.maximum(total, 1e-9)[..., None]
    reference = np.asarray(rgba[:3]) / sum(rgba[:3])
    close = np.abs(chroma - reference).max(axis=-1) < CHROMA_TOLERANCE
    return float((close & (total > 0.15)).mean())


def _hex(rgba) -> int:
    red, green, blue = (int(round(255 * c)) for c in rgba[:3])
    return red << 16 | green << 8 | blue


def _page_objects(page) -> dict[str, tuple[str, int]]:
    """Each object of a saved page (its set_object commands, decoded from the page's data): its
    geometry's type and its material's colour 0xRRGGBB."""
    objects = {}
    for data in re.findall(r'fetch\("data:application/octet-binary;base64,([^"]+)"', page.read_text()):
        command = umsgpack.unpackb(base64.b64decode(data))
        if command.get("type") == "set_object" and command["object"].get("materials"):
            shown = command["object"]
            objects[command["path"]] = (shown["geometries"][0]["type"], shown["materials"][0]["color"])
    return objects


def _folders(dom: str) -> set[str]:
    """The paths of the folders in the page's scene controls (dat.GUI nests ul > li.title)."""
    folders: set[str] = set()

    class Folders(html.parser.HTMLParser):
        def __init__(self) -> None:
            super().__init__()
            self.path: list[str | None] = []
            self.title = False

        def handle_starttag(self, tag, attrs):
            if tag == "ul":
                self.path.append(None)
            self.title = tag == "li" and ("class", "title") in attrs

        def handle_endtag(self, tag):
            if tag == "ul" and self.path:
                self.path.pop()
            self.title = False

        def handle_data(self, data):
            if self.title and self.path and self.path[-1] is None:
                self.path[-1] = data
                folders.add("/".join(name for name in self.path if name))  # dat.GUI's root has no title

    Folders().feed(dom)
    return folders


def _tetrahedron_stl(side: float) -> str:
    points = side * np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    faces = ((0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3))
    facets = "".join(
        "facet normal 0 0 0\nouter loop\n"
        + "".join("vertex {} {} {}\n".format(*points[i]) for i in face)
        + "endloop\nendfacet\n"
        for face in faces
    )
    return f"solid tetra\n{facets}endsolid tetra\n"


# Two times of the bouncing ball [s]: at rest at 1.1 m, and falling through 0.66 m (no contact yet).
BALL_TIMES = (0.0, 0.3)
# The ball moves on screen at least this far between them [px].
MIN_BALL_SHIFT = 20


def _replay_pages(spec, duration, folder):
    """A run's replay page, and the same page with its bodies and contacts hidden (the background)."""
    spec.duration = duration
    log = gaussim.run(spec)
    viewer = Viewer(spec.scene, live=False)
    viewer.replay(log)
    replay = viewer.save_html(folder / "replay.html")
    viewer.meshcat["bodies"].set_property("visible", False)
    viewer.meshcat["contacts"].set_property("visible", False)
    return replay, viewer.save_html(folder / "background.html")


def _bodies_at(pages, at, tmp_path, start=None):
    """The screenshot (H, W, 3) of the replay stopped at ``at`` [s] and the mask (H, W) of the pixels
    that its bodies change (against the background page stopped at the same time); ``start``, a
    screenshot at t = 0, whose time bar a render at a later ``at`` must not show."""
    replay, background = pages
    waits = (4000, 12000, 30000, 60000)  # software WebGL on a loaded 2-core machine can take longer
    for wait_ms in waits:
        drawn = imread(screenshot(replay, tmp_path / f"replay_{at}.png", wait_ms=wait_ms, at=at))[..., :3]
        empty = imread(screenshot(background, tmp_path / f"empty_{at}.png", wait_ms=wait_ms, at=at))[..., :3]
        mask = np.abs(drawn - empty).max(axis=-1) > PIXEL_TOLERANCE
        # both renders at the same time: their time bars agree (Chromium sometimes shoots a page before
        # its replay has loaded, which then shows t = 0 beside the other's t)
        same_time = not mask[-BAR_HEIGHT:].any()
        # both shot before the seek (at t = 0, their bars alike) pass that check: the bar must move too
        seeked = start is None or (np.abs(drawn[-BAR_HEIGHT:] - start[-BAR_HEIGHT:]) > PIXEL_TOLERANCE).any()
        if mask.mean() > NO_BODY_FRACTION and same_time and seeked:
            return drawn, mask
    # the renders, not the framing, are at fault: say so rather than fail a framing check on them
    raise AssertionError(
        f"at t = {at} s the replay and its background never rendered alike in {len(waits)} tries "
        f"(waits {waits} ms): bodies drawn on {mask.mean():.4f} of the pixels, time bars "
        f"{'agree' if same_time else 'differ'}{'' if seeked else ', still at t = 0'}"
    )


def _assert_inside(mask, what):
    rows, cols = np.nonzero(mask)
    assert rows.size, f"{what}: no body drawn"
    h, w = mask.shape
    assert rows.min() >= FRAME_MARGIN and cols.min() >= FRAME_MARGIN, f"{what}: cut off at the top/left"
    assert rows.max() < h - BAR_HEIGHT and cols.max() < w - FRAME_MARGIN, (
        f"{what}: cut off at the bottom/right"
    )


def test_replay_of_a_bouncing_ball_changes_with_time_and_keeps_it_in_frame(tmp_path):
    """Screenshots of the replay stopped at two times by its own time control (page#t=T): the ball is
    inside the frame at both, and lower on screen at the later one."""
    spec = gaussim.load_scene(SCENES / "ball_bounce.toml")
    pages = _replay_pages(spec, 0.8, tmp_path)
    first, early = _bodies_at(pages, BALL_TIMES[0], tmp_path)
    second, late = _bodies_at(pages, BALL_TIMES[1], tmp_path, start=first)
    _assert_inside(early, "the ball at rest at the start")
    _assert_inside(late, "the falling ball")
    scene = (slice(0, first.shape[0] - BAR_HEIGHT), slice(None))
    assert (np.abs(first[scene] - second[scene]).max(axis=-1) > PIXEL_TOLERANCE).mean() > NO_BODY_FRACTION
    shift = np.nonzero(late)[0].mean() - np.nonzero(early)[0].mean()
    assert shift > MIN_BALL_SHIFT, f"the ball moved {shift:.0f} px down the screen, not its fall"


def test_replay_of_the_box_stack_frames_the_top_box(tmp_path):
    """At the start, the stack's three boxes (the top one 0.6 m up) lie inside the frame, each in its
    own colour."""
    spec = gaussim.load_scene(SCENES / "box_stack.toml")
    drawn, mask = _bodies_at(_replay_pages(spec, 0.05, tmp_path), 0.0, tmp_path)
    _assert_inside(mask, "the box stack")
    objects = _page_objects(tmp_path / "replay.html")
    colours = {c for path, (_, c) in objects.items() if path.startswith("/meshcat/bodies/box_stack/")}
    assert len(colours) == 3, "the three boxes of the stack share a colour"


def test_replay_page_shows_time_and_controls_without_a_menu(two_bodies):
    """The overlay's time, play/pause and slider and the legend are on the page as it opens (meshcat's
    own controls stay closed); the seek of #t= is seen in the screenshots of the bouncing ball. (Headless
    Chromium's --dump-dom does not always run the replay's animation before it dumps: the dumped slider
    and time are not checked.)"""
    dom = page_dom(two_bodies[0], wait_ms=4000, at=0.05)
    assert 'id="gaussim-play"' in dom and 'id="gaussim-scrub"' in dom and 'id="gaussim-time"' in dom
    assert "force arrows: 1 m = " in dom and "crate" in dom and "ball" in dom


def test_the_page_of_a_run_that_stopped_early_says_so_and_loads_without_a_script_error(tmp_path):
    """A killed or failed run's page passed for the whole run; its legend now says why it ended. Chromium
    runs it with no uncaught JavaScript error (and page_errors does see one in a page that has it)."""
    spec = gaussim.load_scene(SCENES / "ball_bounce.toml")
    spec.duration = 0.1
    log = gaussim.run(spec)
    with Viewer(spec.scene, live=False) as viewer:
        viewer.replay(log)
        assert 'id="gaussim-stopped"' not in viewer.static_html()
        log.finish(False, "interrupted (Ctrl-C) at step 100, t = 0.1 s")
        viewer.replay(log)
        page = viewer.save_html(tmp_path / "stopped.html")
    said = '<span id="gaussim-stopped">the run did not finish: interrupted (Ctrl-C) at step 100, t = 0.1 s'
    assert said in page.read_text()
    assert page_errors(page) == []
    broken = tmp_path / "broken.html"
    broken.write_text("<html><body><script>undefined_function();</script></body></html>")
    assert page_errors(broken) == ["Uncaught ReferenceError: undefined_function is not defined"]


def test_arrows_have_heads_and_the_length_of_their_force(two_bodies):
    """Each arrow's shaft and cone end where force_scale * |f| says; the page holds a cone per arrow."""
    from gaussim.viewer import HEAD_LENGTH, _arrow

    for length in (1.0, 0.01):  # a long arrow has a full head, a short one a head of half its length
        vector = np.array([3.0, 0.0, 4.0])
        parts, shown = _arrow(np.zeros(3), vector, length / 5.0)
        assert shown
        (shaft_at, shaft_scale), (head_at, head_scale) = parts["shaft"], parts["head"]
        head = head_scale[0] * HEAD_LENGTH
        assert shaft_at[1, 3] + shaft_scale[1] / 2 == pytest.approx(length - head)
        assert head_at[1, 3] + head / 2 == pytest.approx(length)
        assert head == pytest.approx(min(HEAD_LENGTH, length / 2))
        assert np.allclose(parts[""][0][:3, 1], vector / 5.0)  # the arrow's y axis along the force
    objects = _page_objects(two_bodies[0])
    heads = [path for path in objects if path.endswith("/head")]
    shafts = [path for path in objects if path.endswith("/shaft")]
    assert heads and len(heads) == len(shafts)


def test_viewer_draws_into_an_open_visualizer_and_leaves_it_open(tmp_path):
    import meshcat

    from gaussim.viewer import _PageWindow

    scene = gaussim.Scene(bodies={"ball": Body(FreeBody.sphere("ball", 0.1, mass=1.0))})
    mine = meshcat.Visualizer(window=_PageWindow())["my_scene"]
    mine["/other"].set_object(meshcat.geometry.Box([0.1, 0.1, 0.1]))
    with Viewer(scene, meshcat=mine) as viewer:
        assert viewer.meshcat is mine
    mine["/later"].set_object(meshcat.geometry.Box([0.1, 0.1, 0.1]))  # still open after close()
    page = tmp_path / "page.html"
    page.write_text(mine.static_html())
    objects = set(_page_objects(page))
    assert {"/other", "/later"} <= objects
    assert any(path.startswith("/meshcat/my_scene/bodies/ball/") for path in objects), objects
    with pytest.raises(gaussim.GaussimError, match="meshcat.Visualizer"):
        Viewer(scene, meshcat="http://127.0.0.1:7000")


def test_every_body_of_a_large_world_has_its_own_colour():
    bodies = {f"b{k}": Body(FreeBody.sphere(f"b{k}", 0.05, mass=1.0)) for k in range(20)}
    colours = [b.color for b in gaussim.Scene(bodies=bodies).world.bodies.values()]
    assert len(set(colours)) == 20


def test_run_view_serves_then_exits_without_a_terminal(tmp_path):
    """``run --view`` with no terminal on standard input (a script, CI) prints the URL, runs, and exits
    rather than serving forever; with --no-wait too."""
    import subprocess
    import sys

    for flags in ((), ("--no-wait",)):
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "gaussim",
                "run",
                str(SCENES / "ball_bounce.toml"),
                "--view",
                "--quiet",
                "--duration",
                "0.1",
                "--speed",
                "10",
                "--out",
                str(tmp_path / "r"),
                *flags,
            ],  # fmt: skip
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert done.returncode == 0, done.stderr
        assert "watch the run at http://127.0.0.1:" in done.stderr
        assert "viewer closed" in done.stderr, done.stderr

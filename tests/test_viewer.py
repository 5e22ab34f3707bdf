"""The browser viewer as a person sees it: replay pages rendered by headless Chromium, the live
server on 127.0.0.1, and the fallback for missing meshes."""

from __future__ import annotations

import urllib.request

import numpy as np
import pytest
from matplotlib.image import imread

from gaussim.viewer import Viewer, _visual_model, page_dom, screenshot

# A pixel is drawn differently when one of its channels differs by more than this (of 1).
PIXEL_TOLERANCE = 0.1
# The robot covers at least this fraction of the central region of a replay screenshot.
MIN_ROBOT_FRACTION = 0.01
FEET = ("FL", "FR", "HL", "HR")


@pytest.fixture(scope="module")
def pages(solo12_run, tmp_path_factory):
    """The replay page of the run, and the same page with the robot hidden (the background)."""
    log, spec = solo12_run
    folder = tmp_path_factory.mktemp("pages")
    with Viewer(spec.scene) as viewer:
        viewer.replay(log)
        replay = viewer.save_html(folder / "replay.html")
        viewer.meshcat["robot"].set_property("visible", False)
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


def test_missing_visual_meshes_fall_back_to_collision_geometry(solo12):
    visual = solo12.visual_model.copy()
    visual.geometryObjects[0].meshPath = "/nonexistent/base.stl"
    with pytest.warns(UserWarning, match=r"base_link_0: /nonexistent/base.stl"):
        shown = _visual_model(visual, solo12.collision_model)
    assert shown is solo12.collision_model
    assert _visual_model(solo12.visual_model, solo12.collision_model) is solo12.visual_model


def _dom_once_built(page) -> str:
    """The page's DOM once its scripts have built the scene tree: software WebGL on a loaded 2-core
    machine (CI) once took more than the first wait."""
    for wait_ms in (4000, 12000, 30000):
        dom = page_dom(page, wait_ms=wait_ms)
        if "contacts" in dom:
            break
    return dom

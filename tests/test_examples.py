"""Every example runs headless as a test (short durations)."""

import csv
import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import gaussim

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _run(*args: str) -> str:
    result = subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_solo12_drop(tmp_path):
    out = tmp_path / "forces.csv"
    stdout = _run(str(EXAMPLES / "solo12_drop.py"), "--duration", "0.3", "--csv", str(out))
    assert "FL_FOOT_0/ground#0" in stdout and "total" in stdout
    rows = list(csv.DictReader(out.open()))
    assert rows and {r["contact"] for r in rows} >= {"FL_FOOT_0/ground#0", "HR_FOOT_0/ground#0"}


def test_arm_joint_friction():
    """The Z1 let go: its friction holds the joints a free arm swings (joint2 falls 1.77 rad free), and
    the joint that reaches its limit is reported still there, not sliding."""
    stdout = _run(str(EXAMPLES / "arm_joint_friction.py"), "--duration", "0.5")
    rows = {line.split()[0]: line.split() for line in stdout.splitlines()[2:]}
    assert set(rows) == {f"joint{i}" for i in range(1, 7)} | {"jointGripper"}, stdout
    free, rubbed = float(rows["joint2"][2]), float(rows["joint2"][3])
    assert free > 0.5 and abs(rubbed) < 0.5 * free, stdout
    assert float(rows["joint3"][3]) == pytest.approx(1.0, abs=1e-3) and rows["joint3"][-1] == "sticks", stdout


@pytest.mark.parametrize("mode", ["pyramid", "accurate"])
def test_sliding_block(mode):
    stdout = _run(str(EXAMPLES / "sliding_block.py"), "--mode", mode, "--heading", "15")
    assert "stopped after" in stdout


def test_watch_box_stack(tmp_path):
    stdout = _run(str(EXAMPLES / "watch_box_stack.py"), "--duration", "0.1", "--out", str(tmp_path / "stack"))
    assert "replay page:" in stdout
    assert (tmp_path / "stack.html").stat().st_size > 0 and (tmp_path / "stack.png").stat().st_size > 0


def test_free_bodies():
    result = subprocess.run(
        [sys.executable, str(EXAMPLES / "free_bodies.py"), "--dt", "2e-3"], capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr
    assert "rolling:" in result.stdout and "flipping: turned over 1 times" in result.stdout  # at 4.2 s
    assert result.stderr == ""  # no warning about its own body


@pytest.mark.parametrize(
    ("args", "code", "said"),
    [
        (("solo12_drop.py", "--duration", "0"), 2, "argument --duration: must be a finite number > 0, got 0"),
        (("bin_pile.py", "--dt", "nan"), 2, "argument --dt: must be a finite number > 0, got nan"),
        (
            ("incline_friction_study.py", "--frictions", "0.1,abc", "--duration", "0.01"),
            2,
            'incline_friction_study.py: --vary ground.friction: the value "abc"',
        ),
        (  # a write that fails: as the gaussim command, exit 1 naming the path
            ("solo12_drop.py", "--duration", "0.001", "--csv", "/proc/none/forces.csv"),
            1,
            "solo12_drop.py: /proc/none: No such file or directory",
        ),
    ],
)
def test_an_example_refuses_a_bad_argument_in_one_line(tmp_path, args, code, said):
    """A bad number, a value the scene refuses or a path it cannot write: one line on stderr (argparse's
    usage aside), the gaussim command's exit status, no traceback (a duration of 0 crashed solo12_drop
    with an AttributeError)."""
    script, *rest = args
    result = subprocess.run(
        [sys.executable, str(EXAMPLES / script), *rest], capture_output=True, text=True, cwd=tmp_path
    )
    assert result.returncode == code
    assert said in result.stderr and "Traceback" not in result.stderr


def test_a_duration_shorter_than_a_step_runs_one_step(tmp_path):
    """As ``gaussim run``: at least one step (bin_pile crashed on an empty run, UnboundLocalError)."""
    out = tmp_path / "bin"
    _run(str(EXAMPLES / "bin_pile.py"), "--duration", "1e-4", "--out", str(out))
    assert gaussim.RunLog.load(out.with_suffix(".npz")).steps == 1


def _example(name: str):  # type: ignore[no-untyped-def]
    """The example ``name`` as a module, to call its functions (its folder on the path, as when it
    runs: it imports _shared)."""
    if str(EXAMPLES) not in sys.path:
        sys.path.insert(0, str(EXAMPLES))
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("scheme", gaussim.options.SCHEMES)
def test_custom_constraint(scheme):
    """A ball held only by the user's AbovePlane module falls freely, lands when sqrt(2 (z0 - r) / g)
    says (within the step), rests at z = r pushed by m g, and moves as the same ball on gaussim's
    frictionless ground."""
    stdout = _run(str(EXAMPLES / "custom_constraint.py"), "--scheme", scheme)
    assert "pushed up by 9.810000 N" in stdout
    example, dt, z0 = _example("custom_constraint"), 1e-3, 0.5
    custom = example.drop(False, z0, dt=dt, scheme=scheme)
    r, mass = example.RADIUS, gaussim.load_robot("ball", floating_base=True).mass
    assert abs(custom.landed - np.sqrt(2 * (z0 - r) / example.G)) <= dt
    k = np.arange(len(custom.t))[custom.t < custom.landed - dt / 2]  # the steps before the landing one
    falling = z0 - example.G * dt**2 * k * (k + 1) / 2  # free fall, v+ = v - g dt then z+ = z + dt v+
    np.testing.assert_allclose(custom.z[k], falling, rtol=0, atol=1e-12)
    np.testing.assert_array_less(r, custom.z[k])
    assert abs(custom.z[-1] - r) < 1e-9
    assert custom.push == pytest.approx(mass * example.G, rel=1e-9)
    np.testing.assert_allclose(custom.z, example.drop(True, z0, dt=dt, scheme=scheme).z, rtol=0, atol=1e-12)


def test_a_custom_constraint_is_checked_once():
    """What the Simulator refuses from a user: not a ConstraintModule, or a name already taken."""
    example = _example("custom_constraint")
    ball = gaussim.load_robot("ball", floating_base=True)
    scene = gaussim.Scene(ball)
    with pytest.raises(gaussim.InvalidOptions, match=r"constraints\[0\]: must be a gaussim.constraints"):
        gaussim.Simulator(scene, constraints=[object()])
    plane = example.AbovePlane(ball, "ball", height=0.1)
    with pytest.raises(gaussim.InvalidOptions, match="constraints\\[1\\]: the name 'above_plane' is taken"):
        gaussim.Simulator(scene, constraints=[plane, plane])
    plane.name = "contact"
    with pytest.raises(gaussim.InvalidOptions, match="the name 'contact' is taken; taken: contact, limit"):
        gaussim.Simulator(scene, constraints=[plane])
    with pytest.raises(gaussim.FrameNotFound, match="no frame 'hand'"):
        example.AbovePlane(ball, "hand", height=0.1)


def test_the_passes_pose_again_only_the_modules_that_asked_and_not_after_the_last():
    """Two user modules holding a ball resting on a plane and just above another: one asks for another
    pass after every QP,
    the other never does and compares equal to anything. Each step poses the first once per QP
    (Options.friction_iterations of them) and the second once: the rows of the last QP's answer are
    not posed again, and a module is told from another by identity."""
    example = _example("custom_constraint")

    class Counted(example.AbovePlane):  # type: ignore[name-defined,misc]
        def __init__(self, name: str, asks: bool, height: float) -> None:
            super().__init__(ball, "ball", height=height)
            self.name, self.asks, self.posed = name, asks, 0

        def rows(self, ctx):  # type: ignore[no-untyped-def]
            self.posed += 1
            return super().rows(ctx)

        def refine(self, ctx, rows, x, multipliers):  # type: ignore[no-untyped-def]
            return self.asks

        def __eq__(self, other: object) -> bool:
            return True

        __hash__ = object.__hash__

    ball = gaussim.load_robot("ball", floating_base=True)
    # the quiet plane 2 mm lower: within the contact margin (posed), not touching (no degenerate QP)
    asking, quiet = Counted("asking", True, example.RADIUS), Counted("quiet", False, example.RADIUS - 2e-3)
    passes = 3
    options = gaussim.Options(friction_iterations=passes)
    sim = gaussim.Simulator(gaussim.Scene(ball, ground=None), options, constraints=[asking, quiet])
    q = ball.neutral()
    q[2] = example.RADIUS
    state = sim.reset(q)
    steps = 5
    for _ in range(steps):
        state = sim.step(state)
    assert sim.last_step is not None and len(sim.last_step.certificates) == passes
    assert (asking.posed, quiet.posed) == (steps * passes, steps)


def _page_holds(page: Path, names: list[str]) -> None:
    """The replay page's scene tree (its controls, once its scripts ran) has a node for each name."""
    from gaussim.viewer import page_dom

    for wait_ms in (4000, 12000, 30000):  # software WebGL on a loaded 2-core machine can take longer
        dom = page_dom(page, wait_ms=wait_ms)
        # a folder of meshcat's controls (the overlay's legend names the bodies too)
        missing = [name for name in names if f'<li class="title">{name}<' not in dom]
        if not missing:
            break
    assert not missing, f"the replay page draws no {missing}"


def _replay(out: Path, bodies: list[str]) -> gaussim.RunLog:
    """The example's run log (every step) and replay page (every body)."""
    log = gaussim.RunLog.load(out.with_suffix(".npz"))
    assert log.complete and log.steps > 0
    _page_holds(out.with_suffix(".html"), bodies)
    return log


def test_solo_pushes_crate(tmp_path):
    out = tmp_path / "push"
    stdout = _run(
        str(EXAMPLES / "solo_pushes_crate.py"), "--duration", "0.8", "--distance", "0.02", "--out", str(out)
    )
    moved = float(stdout.split("crate displacement: ")[1].split(" m")[0])
    assert moved > 0.03, stdout  # pushed 8 cm in 0.8 s
    log = _replay(out, ["solo", "crate"])
    assert {"crate/box/ground"} <= set(
        log.contact_geometry[i] + "/" + log.contact_obstacle[i] for i in range(len(log.contact_names))
    )


def test_panda_sweeps_cube(tmp_path):
    out = tmp_path / "sweep"
    stdout = _run(str(EXAMPLES / "panda_sweeps_cube.py"), "--duration", "1.0", "--out", str(out))
    travel = float(stdout.split("cube travel: ")[1].split(" m")[0])
    assert travel > 0.1, stdout
    log = _replay(out, ["arm", "cube", "table"])
    assert any(name.startswith("arm/panda_") and "/cube/box" in name for name in log.contact_names)


def test_bin_pile(tmp_path):
    out = tmp_path / "pile"
    stdout = _run(str(EXAMPLES / "bin_pile.py"), "--duration", "0.05", "--out", str(out))
    assert "every object inside the bin: True" in stdout and "uncertified QP: 0" in stdout
    _replay(out, ["box0", "ball1", "capsule2", "ball19", "floor", "wall_x+"])


def test_solo_bump(tmp_path):
    out = tmp_path / "bump"
    stdout = _run(str(EXAMPLES / "solo_bump.py"), "--duration", "0.5", "--apart", "0.45", "--out", str(out))
    assert "first touch at t = " in stdout, stdout
    _replay(out, ["left", "right"])

"""Peer engines for the benchmark, run on the same robots in the same sweep when installed
(``pip install -e '.[bench]'``). MuJoCo only for now, on Solo-12 standing.

MuJoCo facts this relies on (measured here): its URDF import welds the root link to the world (the
model is saved as MJCF and given a free joint), does not resolve ``package://`` meshes (collision
geometry is replaced by primitives: sphere feet of gaussim's foot size), and ``fusestatic="false"``
keeps the foot bodies; Pinocchio's quaternions are xyzw, MuJoCo's wxyz.
"""

from __future__ import annotations

import re
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..robot import Robot, load_robot

G = 9.81
FEET = ("FL", "FR", "HL", "HR")
KP, KD = 5.0, 0.2  # robots/scenes/solo12_standing.toml's PD hold


@dataclass(frozen=True)
class Peer:
    """An engine other than gaussim: the cases it runs and how (``run(case, quick)`` -> metrics)."""

    cases: tuple[str, ...]
    run: Callable[[str, bool], dict[str, float]]


def mujoco_model(robot: Robot, dt: float = 1e-3):  # type: ignore[no-untyped-def]
    """Solo-12 in MuJoCo: URDF without meshes, sphere feet of gaussim's foot size, a free joint, a floor."""
    import mujoco

    text = Path(robot.urdf).read_text()
    text = re.sub(r"<visual>.*?</visual>", "", text, flags=re.S)
    text = re.sub(r"<collision>.*?</collision>", "", text, flags=re.S)
    text = text.replace(
        "</robot>", '<mujoco><compiler fusestatic="false" discardvisual="true"/></mujoco></robot>'
    )
    spec_model = mujoco.MjModel.from_xml_string(text)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "solo12.xml"
        mujoco.mj_saveLastXML(str(path), spec_model)
        xml = path.read_text()
    # foot spheres: radius and centre from the collision hull of the foot in gaussim's model
    geometry = robot.collision_model.geometryObjects[robot.geometry_id("FL_FOOT_0")]
    points = np.asarray(geometry.geometry.convex.points())
    radius = float(np.max(np.linalg.norm(points - points.mean(axis=0), axis=1)))
    pos = " ".join(f"{x:.5f}" for x in geometry.placement.act(points.mean(axis=0)))
    for leg in FEET:
        xml = re.sub(
            rf'(<body name="{leg}_LOWER_LEG"[^>]*>)',
            rf'\1<geom type="sphere" size="{radius:.5f}" pos="{pos}" friction="0.8"/>',
            xml,
        )
    xml = re.sub(r'(<body name="base_link"[^>]*>)', r"\1<freejoint/>", xml, count=1)
    xml = xml.replace("<worldbody>", '<worldbody><geom type="plane" size="5 5 0.1" friction="0.8"/>', 1)
    xml = xml.replace("<compiler", f'<option timestep="{dt}" integrator="implicitfast"/><compiler', 1)
    return mujoco.MjModel.from_xml_string(xml)


def mujoco_standing(solver: str, cone: str) -> Callable[[str, bool], dict[str, float]]:
    """MuJoCo on Solo-12 standing under the same PD hold as gaussim's solo12 case: dropped 1 cm,
    0.3 s to land, then measured (the same metrics where MuJoCo has them)."""

    def run(case: str, quick: bool) -> dict[str, float]:
        import mujoco

        robot = load_robot("solo12")
        model = mujoco_model(robot)
        model.opt.solver = {"newton": mujoco.mjtSolver.mjSOL_NEWTON, "pgs": mujoco.mjtSolver.mjSOL_PGS}[
            solver
        ]
        model.opt.cone = {
            "pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL,
            "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC,
        }[cone]
        data = mujoco.MjData(model)
        q_ref = robot.configuration("standing")
        data.qpos[:3] = q_ref[:3]
        data.qpos[2] += 0.01  # the scene's ground clearance (its feet start 1 cm up, as gaussim's)
        data.qpos[3:7] = [q_ref[6], *q_ref[3:6]]  # Pinocchio xyzw -> MuJoCo wxyz
        data.qpos[7:] = q_ref[7:]
        seconds, penetration = [], 0.0
        wrench = np.zeros(6)
        dt = model.opt.timestep
        for _ in range(round((0.3 + (0.2 if quick else 1.0)) / dt)):
            data.qfrc_applied[6:] = KP * (q_ref[7:] - data.qpos[7:]) - KD * data.qvel[6:]
            start = time.perf_counter()
            mujoco.mj_step(model, data)
            seconds.append(time.perf_counter() - start)
            if data.ncon:
                penetration = max(penetration, -float(data.contact.dist.min()))
        normal = 0.0
        for i in range(data.ncon):
            mujoco.mj_contactForce(model, data, i, wrench)
            normal += wrench[0] * data.contact[i].frame[2]  # the normal is the contact frame's x axis
        weight = float(np.sum(model.body_mass)) * G
        times = np.array(seconds)
        return {
            "error": abs(normal - weight) / weight,
            "penetration": penetration,
            "us_per_step": float(np.median(times)) * 1e6,
            "us_per_step_p90": float(np.percentile(times, 90)) * 1e6,
            "wall_per_sim_s": float(times.sum()) / (len(times) * dt),
        }

    return run


PEERS: dict[str, Peer] = {
    f"mujoco-{solver}-{cone}": Peer(("solo12",), mujoco_standing(solver, cone))
    for solver in ("newton", "pgs")
    for cone in ("pyramidal", "elliptic")
}


def available() -> list[str]:
    """The peers installed on this machine."""
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return []
    return list(PEERS)

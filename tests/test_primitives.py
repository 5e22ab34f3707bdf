"""Compiled primitive pairs against coal and closed forms: box on box (separating axes and a clipped
face patch), capsule on the ground (a two-vertex hull rounded by its radius)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import lsq_linear

import gaussim
from gaussim import FreeBody
from gaussim.collision import ContactDetector
from gaussim.collision.boxes import BoxPairs
from gaussim.collision.ground import GroundHulls
from gaussim.collision.narrow import NarrowPhase

# Both compute the same closest points of two boxes in floating point; they may round differently [m].
AGREEMENT = 1e-9
# coal's EPA (the reference for overlapping boxes) stops this far from the exact depth, and its
# normal this far from the face's, even at its tightest tolerance: points move by the normal's error
# times the patch's reach [m].
EPA_AGREEMENT = 1e-8
NORMAL_AGREEMENT = 1e-6
MARGIN = 1e-3
HALF_A, HALF_B = np.array([0.05, 0.04, 0.03]), np.array([0.1, 0.06, 0.05])


def _tight(pairs, index) -> NarrowPhase:
    """coal's narrow phase at its tightest GJK/EPA tolerances, the reference."""
    narrow = NarrowPhase(pairs, index)
    for request in (narrow.request, narrow.retry_request):
        request.gjk_tolerance = request.epa_tolerance = 1e-15
        request.gjk_max_iterations = request.epa_max_iterations = 1000
    return narrow


def _box_poses(count: int, seed: int) -> Iterator[tuple[pin.SE3, pin.SE3]]:
    """Placements of box a (half sides HALF_A) and box b (HALF_B): a third at random, the others with
    a face of a resting on a face of b, tilted by 0 to 0.03 rad, within MARGIN of touching or
    overlapping by as much."""
    rng = np.random.default_rng(seed)
    for k in range(count):
        Rb, pb = pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3)), rng.uniform(-0.1, 0.1, 3)
        if k % 3 == 0:
            Ra, pa = pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3)), pb + rng.uniform(-0.2, 0.2, 3)
        else:
            axis = int(rng.integers(3))
            n = Rb[:, axis] * rng.choice([-1.0, 1.0])
            tilt = [0.0, 1e-6, 1e-3, 3e-2][int(rng.integers(4))]
            turn = np.eye(3)[rng.permutation(3)]
            turn[:, 0] *= np.linalg.det(turn)
            Ra = Rb @ turn @ pin.rpy.rpyToMatrix(*rng.uniform(-tilt, tilt, 3))
            extent = np.abs(Ra.T @ n) @ HALF_A
            slide = rng.uniform(-0.08, 0.08, 3)
            pa = (
                pb
                + n * (HALF_B[axis] + extent + rng.uniform(-MARGIN / 2, MARGIN / 2))
                + slide
                - (slide @ n) * n
            )
        yield pin.SE3(Ra, pa), pin.SE3(Rb, pb)


def _distance(a: pin.SE3, b: pin.SE3) -> float:
    """The distance of the two boxes (scipy's bounded least squares over their local coordinates)."""
    A = np.hstack([a.rotation, -b.rotation])
    bounds = np.concatenate([HALF_A, HALF_B])
    solution = lsq_linear(
        A, b.translation - a.translation, bounds=(-bounds, bounds), method="bvls", tol=1e-15
    )
    return float(np.linalg.norm(A @ solution.x - (b.translation - a.translation)))


@pytest.mark.parametrize("fixed", [False, True])
def test_boxes_on_boxes_match_coal(fixed):
    """Box a against box b (another body's, or a fixed obstacle) at random and resting poses: the
    compiled pairs find a contact exactly when coal does; where they answer themselves (not handing
    the pair to coal), their gap is the boxes' distance (scipy) or coal's depth, and their patch is
    coal's, point for point in the same order."""
    a = FreeBody.box("a", tuple(2 * HALF_A), mass=1.0)
    b = FreeBody.box("b", tuple(2 * HALF_B), mass=1.0)
    obstacle = gaussim.Box("b", tuple(2 * HALF_B))
    answered = 0
    for k, (pose_a, pose_b) in enumerate(_box_poses(240, seed=3)):
        if fixed:
            obstacle = gaussim.Box(
                "b", tuple(2 * HALF_B), position=pose_b.translation, rotation=pose_b.rotation
            )
            scene = gaussim.Scene(bodies={"a": a}, obstacles=[obstacle])
            q = pin.SE3ToXYZQUAT(pose_a)
        else:
            scene = gaussim.Scene(bodies={"a": a, "b": b})
            q = np.concatenate([pin.SE3ToXYZQUAT(pose_a), pin.SE3ToXYZQUAT(pose_b)])
        detector = ContactDetector(scene, MARGIN)
        assert [type(r) for r in detector.routines] == [BoxPairs]
        data = scene.robot.model.createData()
        pin.forwardKinematics(scene.robot.model, data, q)
        mine, least = detector.routines[0].detect(data, MARGIN)
        current, _ = NarrowPhase(detector.pairs, [0]).detect(data, MARGIN)
        reference, _ = _tight(detector.pairs, [0]).detect(data, MARGIN)
        assert len(mine) == len(current) == len(reference), k
        if not mine or all(np.array_equal(x, y) for x, y in zip(mine[0], current[0])):
            continue  # no contact, or coal's own answer
        answered += 1
        assert least <= _distance(pose_a, pose_b) + AGREEMENT
        _, points, normals, gaps = mine[0]
        _, points_ref, normals_ref, gaps_ref = reference[0]
        if gaps[0] > 0:
            assert gaps == pytest.approx(_distance(pose_a, pose_b), abs=AGREEMENT), k
        np.testing.assert_allclose(gaps, gaps_ref, atol=EPA_AGREEMENT, err_msg=str(k))
        np.testing.assert_allclose(normals, normals_ref, atol=NORMAL_AGREEMENT, err_msg=str(k))
        assert points.shape == points_ref.shape, k
        np.testing.assert_allclose(points, points_ref, atol=EPA_AGREEMENT, err_msg=str(k))
    assert answered >= 80, answered  # most resting poses are answered by the compiled pairs


def test_a_box_resting_on_a_box_touches_at_its_corners():
    """A box centred on a larger one: the four corners of its bottom face, at its gap, normal up."""
    scene = gaussim.Scene(
        bodies={"a": FreeBody.box("a", tuple(2 * HALF_A), mass=1.0)},
        obstacles=[gaussim.Box("b", tuple(2 * HALF_B))],
    )
    detector = ContactDetector(scene, MARGIN)
    data = scene.robot.model.createData()
    pin.forwardKinematics(
        scene.robot.model, data, np.array([0, 0, HALF_B[2] + HALF_A[2] + 2e-4, 0, 0, 0, 1.0])
    )
    contacts = detector.detect(data)
    corners = np.array([[x, y, HALF_B[2] + 2e-4] for x in (-1, 1) for y in (-1, 1)]) * [*HALF_A[:2], 1]
    np.testing.assert_allclose(contacts.point, corners, atol=1e-15)
    np.testing.assert_allclose(contacts.gap, 2e-4, atol=1e-15)
    np.testing.assert_allclose(contacts.normal, np.tile([0, 0, 1.0], (4, 1)), atol=1e-15)


@pytest.mark.parametrize("normal", [(0.0, 0.0, 1.0), (0.3, -0.2, 1.0)])
def test_a_capsule_on_ground_matches_coal(normal):
    """A capsule above a (tilted) ground, in the compiled pass: its deepest point and gap are coal's;
    lying flat it touches at both ends of its segment, each with its own gap."""
    radius, length = 0.02, 0.06
    ground = gaussim.Ground(normal=normal, height=-0.1)
    scene = gaussim.Scene(bodies={"c": FreeBody.capsule("c", radius, length, mass=1.0)}, ground=ground)
    detector = ContactDetector(scene, 10.0)
    assert [type(r) for r in detector.routines] == [GroundHulls]
    reference = _tight(detector.pairs, [0])
    data = scene.robot.model.createData()
    rng = np.random.default_rng(0)
    n = np.asarray(ground.normal)
    for _ in range(50):
        R = pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3))
        pin.forwardKinematics(scene.robot.model, data, pin.SE3ToXYZQUAT(pin.SE3(R, rng.uniform(-1, 1, 3))))
        contacts = detector.detect(data)
        ((_, point, _, gap),) = reference.detect(data, 10.0)[0]
        deepest = int(np.argmin(contacts.gap))
        assert contacts.gap[deepest] == pytest.approx(gap.min(), abs=AGREEMENT)
        np.testing.assert_allclose(contacts.normal, np.tile(n, (len(contacts), 1)), atol=1e-15)
        if len(contacts) == 1:
            np.testing.assert_allclose(contacts.point[0], point[0], atol=AGREEMENT)
    # lying flat (its axis across the ground's normal), 1e-4 above the ground
    axis = np.cross(n, [1.0, 0, 0])
    axis /= np.linalg.norm(axis)
    local = detector.pairs[0].local  # the capsule in its body's frame, its segment along its z
    placed = pin.SE3(np.column_stack([np.cross(n, axis), n, axis]), n * (-0.1 + radius + 1e-4))
    pin.forwardKinematics(scene.robot.model, data, pin.SE3ToXYZQUAT(placed * local.inverse()))
    centre = placed.translation
    contacts = detector.detect(data)
    ends = centre + np.outer([-length / 2, length / 2], axis) - radius * n
    np.testing.assert_allclose(contacts.point, ends, atol=1e-15)
    np.testing.assert_allclose(contacts.gap, 1e-4, atol=1e-15)

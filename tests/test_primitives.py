"""Compiled primitive pairs against coal and closed forms: box on box (separating axes and a clipped
face patch), capsule on the ground (a two-vertex hull rounded by its radius)."""

from __future__ import annotations

from collections.abc import Iterator

import coal
import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import lsq_linear

import gaussim
from gaussim import FreeBody
from gaussim.bench.scenes import bin_pile
from gaussim.collision import ContactDetector, driver
from gaussim.collision.boxes import BoxPairs
from gaussim.collision.ground import GroundHulls
from gaussim.collision.narrow import NarrowPhase
from gaussim.collision.primitives import PrimitivePairs

# Both compute the same closest points of two boxes in floating point; they may round differently [m].
AGREEMENT = 1e-9
# coal's EPA (the reference for overlapping boxes) stops this far from the exact depth, and its
# normal this far from the face's, even at its tightest tolerance: points move by the normal's error
# times the patch's reach [m].
EPA_AGREEMENT = 1e-8
NORMAL_AGREEMENT = 1e-6
MARGIN = 1e-3
STILL = np.zeros(1)  # no pair turns within the step (the routines read one pair's entry)
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


def _tilted_face_poses(count: int, seed: int) -> Iterator[tuple[pin.SE3, pin.SE3]]:
    """Placements of box a face down on a face of box b, turned about their normal by any angle and
    tilted by 1e-3 to 2e-2 rad (a box settling on another in a bin), within MARGIN of touching or
    overlapping by as much, slid so that a's face covers part of b's: where an edge axis separates
    them best, each still presents a face along it."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        Rb, pb = pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3)), rng.uniform(-0.1, 0.1, 3)
        axis = int(rng.integers(3))
        n = Rb[:, axis] * rng.choice([-1.0, 1.0])
        down = int(rng.integers(3))  # a's face on b: its axis `down` against n
        flip = np.eye(3)[[(down + 1) % 3, (down + 2) % 3, down]].T  # a's axis `down` -> z
        spin = pin.exp3(np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)]))
        tilt = pin.exp3(np.r_[rng.normal(size=2), 0.0] / np.sqrt(2) * rng.uniform(1e-3, 2e-2))
        frame = np.column_stack([Rb[:, (axis + 1) % 3], Rb[:, (axis + 2) % 3], Rb[:, axis]])
        frame[:, 2] = n
        frame[:, 0] = np.cross(frame[:, 1], n)
        Ra = frame @ tilt @ spin @ np.diag([1.0, 1.0, -1.0]) @ np.diag([1.0, -1.0, 1.0]) @ flip.T
        extent = np.abs(Ra.T @ n) @ HALF_A
        slide = frame[:, :2] @ rng.uniform(-0.06, 0.06, 2)
        pa = pb + n * (HALF_B[axis] + extent + rng.uniform(-MARGIN / 2, MARGIN / 2)) + slide
        yield pin.SE3(Ra, pa), pin.SE3(Rb, pb)


def _distance(a: pin.SE3, b: pin.SE3) -> float:
    """The distance of the two boxes (scipy's bounded least squares over their local coordinates)."""
    A = np.hstack([a.rotation, -b.rotation])
    bounds = np.concatenate([HALF_A, HALF_B])
    solution = lsq_linear(
        A, b.translation - a.translation, bounds=(-bounds, bounds), method="bvls", tol=1e-15
    )
    return float(np.linalg.norm(A @ solution.x - (b.translation - a.translation)))


def _edge_poses(count: int, seed: int) -> Iterator[tuple[pin.SE3, pin.SE3]]:
    """Placements of box a and box b at random orientations with the line of an edge of a crossing the
    line of an edge of b, mostly inside both edges (a fifth beyond an end), within MARGIN of touching
    or overlapping by as much along their common normal."""
    rng = np.random.default_rng(seed)
    while count:
        Ra, Rb = (pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3)) for _ in range(2))
        i, j = rng.integers(3, size=2)
        n = np.cross(Ra[:, i], Rb[:, j])
        if np.linalg.norm(n) < 0.3:
            continue
        n /= np.linalg.norm(n)  # from b towards a
        o_a = -sum(np.sign(n @ Ra[:, c]) * HALF_A[c] * Ra[:, c] for c in range(3) if c != i)
        o_b = sum(np.sign(n @ Rb[:, c]) * HALF_B[c] * Rb[:, c] for c in range(3) if c != j)
        s, t = rng.uniform(-1.2, 1.2) * HALF_A[i], rng.uniform(-1.2, 1.2) * HALF_B[j]  # some beyond
        gap = rng.uniform(-MARGIN / 2, MARGIN / 2)
        pb = rng.uniform(-0.1, 0.1, 3)
        pa = pb + o_b + t * Rb[:, j] + gap * n - o_a - s * Ra[:, i]
        count -= 1
        yield pin.SE3(Ra, pa), pin.SE3(Rb, pb)


def _compare_boxes(poses: Iterator[tuple[pin.SE3, pin.SE3]], fixed: bool) -> tuple[int, int, int]:
    """Box a against box b (another body's, or a fixed obstacle) at each of ``poses``: the compiled
    pairs find a contact exactly when coal does; where they answer themselves (not handing the pair
    to coal), their gap is the boxes' distance (scipy) or coal's depth, and their patch is coal's,
    point for point in the same order. Returns how many poses they answered, of those how many at one
    point, and of those how many along a face's normal (a corner over a face; two edges touch along
    their cross product)."""
    a = FreeBody.box("a", tuple(2 * HALF_A), mass=1.0)
    b = FreeBody.box("b", tuple(2 * HALF_B), mass=1.0)
    answered = ones = corners = 0
    for k, (pose_a, pose_b) in enumerate(poses):
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
        mine, least = detector.routines[0].detect(data, MARGIN, STILL)
        current, _ = NarrowPhase(detector.pairs, [0]).detect(data, MARGIN, STILL)
        reference, _ = _tight(detector.pairs, [0]).detect(data, MARGIN, STILL)
        assert len(mine) == len(current) == len(reference), k
        if not mine or all(np.array_equal(x, y) for x, y in zip(mine[0], current[0])):
            continue  # no contact, or coal's own answer
        answered += 1
        if len(mine[0][1]) == 1:
            ones += 1
            axes = np.hstack([pose_a.rotation, pose_b.rotation])
            corners += np.abs(mine[0][2][0] @ axes).max() > 1 - 1e-12
        assert least <= _distance(pose_a, pose_b) + AGREEMENT
        _, points, normals, gaps = mine[0]
        _, points_ref, normals_ref, gaps_ref = reference[0]
        if gaps[0] > 0:
            assert gaps == pytest.approx(_distance(pose_a, pose_b), abs=AGREEMENT), k
        np.testing.assert_allclose(gaps, gaps_ref, atol=EPA_AGREEMENT, err_msg=str(k))
        np.testing.assert_allclose(normals, normals_ref, atol=NORMAL_AGREEMENT, err_msg=str(k))
        assert points.shape == points_ref.shape, k
        np.testing.assert_allclose(points, points_ref, atol=EPA_AGREEMENT, err_msg=str(k))
    return answered, ones, corners


@pytest.mark.parametrize("fixed", [False, True])
def test_boxes_on_boxes_match_coal(fixed):
    """At random and resting poses (see :func:`_compare_boxes`): most resting poses are answered by the
    compiled pairs, and corners over a face at one point."""
    answered, _, corners = _compare_boxes(_box_poses(240, seed=3), fixed)
    assert answered >= 80 and corners >= 10, (answered, corners)


@pytest.mark.parametrize("fixed", [False, True])
def test_boxes_crossing_edge_to_edge_match_coal(fixed):
    """The lines of two edges crossing, mostly inside both edges (see :func:`_compare_boxes`): answered
    at coal's witness point on the robot's edge, or at coal's patch of the two edges."""
    answered, ones, corners = _compare_boxes(_edge_poses(120, seed=4), fixed)
    assert ones - corners >= 40 and answered > ones, (answered, ones, corners)


@pytest.mark.parametrize("fixed", [False, True])
def test_tilted_faces_across_an_edge_axis_match_coal(fixed):
    """A box settling face down on another, turned and tilted (see :func:`_tilted_face_poses`): where
    an edge axis separates them best and each presents a face (or 3 of its corners, tilted across the
    1 mm tolerance) along it, and where a face's axis does and the other box presents 3 corners, the
    compiled pairs clip them as coal does (its patch, point for point), no longer handing the pair to
    coal."""
    answered, ones, _ = _compare_boxes(_tilted_face_poses(200, seed=5), fixed)
    assert answered - ones >= 180, (answered, ones)  # 186; 167 with faces of 4 corners only, 104 with none


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
        ((_, point, _, gap),) = reference.detect(data, 10.0, STILL)[0]
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


# coal's closed forms (sphere-sphere, sphere-capsule, sphere-box, capsule-capsule), computed in the
# same order of operations: they agree to round-off [m].
SAME = 1e-12
# coal's GJK (a capsule against a box) at its tightest tolerance: its box support moves a box's
# negative sides out by 1e-10 of the half side once a query in the process had a zero direction
# component (a function-static), and its normal stops this far from the closest points' [m].
GJK_AGREEMENT = 1e-9
GJK_NORMAL_AGREEMENT = 1e-7
SPHERE_RADIUS, CAPSULE_RADIUS, CAPSULE_LENGTH = 0.03, 0.02, 0.06
OBSTACLE_BOX, OBSTACLE_SPHERE = np.array([0.2, 0.1, 0.05]), 0.05
ORIGIN = pin.SE3.Identity()
PRIMITIVE_CASES = [
    (a, b, fixed)
    for a in ("sphere", "capsule", "box")
    for b in ("sphere", "capsule", "box")
    for fixed in (False, True)
    if not (a == b == "box") and not (fixed and b == "capsule")  # fixed obstacles: boxes, spheres
]


def _body(kind: str, name: str) -> FreeBody:
    """A free sphere, capsule (along its z) or box of the sizes above."""
    if kind == "sphere":
        return FreeBody.sphere(name, SPHERE_RADIUS, mass=1.0)
    if kind == "capsule":
        return FreeBody.capsule(name, CAPSULE_RADIUS, CAPSULE_LENGTH, mass=1.0)
    return FreeBody.box(name, tuple(2 * HALF_A), mass=1.0)


def _scene(a: str, b: str, fixed: bool, pose_b: pin.SE3 = ORIGIN) -> gaussim.Scene:
    """Body ``a`` against body ``b``, or against a fixed box (OBSTACLE_BOX) or sphere at ``pose_b``."""
    if not fixed:
        return gaussim.Scene(bodies={"a": _body(a, "a"), "b": _body(b, "b")})
    if b == "sphere":
        obstacle = gaussim.Sphere("b", OBSTACLE_SPHERE, position=pose_b.translation)
    else:
        obstacle = gaussim.Box(
            "b", tuple(OBSTACLE_BOX), position=pose_b.translation, rotation=pose_b.rotation
        )
    return gaussim.Scene(bodies={"a": _body(a, "a")}, obstacles=[obstacle])


def _place(scene: gaussim.Scene, data: pin.Data, pose_a: pin.SE3, pose_b: pin.SE3) -> None:
    """Forward kinematics with body a at ``pose_a`` (and body b, when it is one, at ``pose_b``)."""
    q = pin.SE3ToXYZQUAT(pose_a)
    if len(scene.bodies) == 2:
        q = np.concatenate([q, pin.SE3ToXYZQUAT(pose_b)])
    pin.forwardKinematics(scene.robot.model, data, q)


def _asking(routine: PrimitivePairs) -> list[str]:
    """The names of the pairs ``routine`` hands to coal, as it does."""
    asked: list[str] = []
    collide = routine.coal.collide

    def counted(pair, data):
        asked.append(pair.name)
        return collide(pair, data)

    routine.coal.collide = counted  # type: ignore[method-assign]
    return asked


def _segment_box_distance(capsule: pin.SE3, box: pin.SE3, half: np.ndarray) -> float:
    """The distance of a capsule's segment (along its z) to a box (scipy's bounded least squares over
    the segment's parameter and the box's local coordinates), less the capsule's radius."""
    axis = capsule.rotation[:, 2] * CAPSULE_LENGTH
    start = capsule.translation - axis / 2
    A = np.column_stack([axis, -box.rotation])
    bounds = np.concatenate([[0.5], half])
    solution = lsq_linear(
        A, box.translation - start - axis / 2, bounds=(-bounds, bounds), method="bvls", tol=1e-15
    )
    return float(np.linalg.norm(A @ solution.x - (box.translation - start - axis / 2))) - CAPSULE_RADIUS


@pytest.mark.parametrize(("a", "b", "fixed"), PRIMITIVE_CASES)
def test_primitive_pairs_match_coal(a, b, fixed):
    """Shape a against shape b (another body's, or a fixed obstacle) near contact, at random poses and
    at poses with their axes aligned (a capsule lying on a face or on another capsule): the compiled
    pairs find a contact exactly when coal does, and where they answer themselves their points (as
    many), normal and gap are those of coal at its tightest tolerances; a capsule's gap on a box is
    also the distance of its segment to the box (scipy) less its radius."""
    rng = np.random.default_rng(7)
    pose_b = pin.SE3(pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3)), rng.uniform(-0.1, 0.1, 3))
    scene = _scene(a, b, fixed, pose_b)
    detector = ContactDetector(scene, MARGIN)
    assert [type(r) for r in detector.routines] == [PrimitivePairs]
    routine = detector.routines[0]
    asked = _asking(routine)
    reference = _tight(detector.pairs, [0])
    data = scene.robot.model.createData()
    agreement, normal_agreement = (
        (GJK_AGREEMENT, GJK_NORMAL_AGREEMENT) if {a, b} == {"capsule", "box"} else (SAME, SAME)
    )
    samples, answered, patches = 90, 0, 0
    for k in range(samples):
        R = pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3))
        towards = rng.normal(size=3)
        if k % 3 == 0:  # axes aligned to within 0 to 1e-4 rad, along a face normal of b
            R = pose_b.rotation @ pin.rpy.rpyToMatrix(
                *(rng.integers(0, 4, 3) * np.pi / 2 + rng.choice([0.0, 1e-7, 1e-4], 3))
            )
            towards = (
                pose_b.rotation[:, rng.integers(3)] * rng.choice([-1.0, 1.0]) + rng.normal(size=3) * 0.05
            )
        towards /= np.linalg.norm(towards)
        low, high = 0.0, 0.5  # the offset along ``towards`` at which they touch, by bisection on coal
        reference.use_margin(0.0)
        for _ in range(50):
            middle = (low + high) / 2
            _place(scene, data, pin.SE3(R, pose_b.translation + middle * towards), pose_b)
            hit, _ = reference.collide(detector.pairs[0], data)
            low, high = (middle, high) if hit is not None else (low, middle)
        pose_a = pin.SE3(R, pose_b.translation + (low + rng.uniform(-MARGIN, MARGIN)) * towards)
        _place(scene, data, pose_a, pose_b)
        asked.clear()
        mine, least = routine.detect(data, MARGIN, STILL)
        expected, _ = reference.detect(data, MARGIN, STILL)
        assert len(mine) == len(expected), k
        if asked or not mine:
            continue
        answered += 1
        (_, points, normals, gaps), (_, points_ref, normals_ref, gaps_ref) = mine[0], expected[0]
        assert points.shape == points_ref.shape, k
        patches += len(points) == 2
        np.testing.assert_allclose(points, points_ref, atol=agreement, err_msg=str(k))
        np.testing.assert_allclose(gaps, gaps_ref, atol=agreement, err_msg=str(k))
        np.testing.assert_allclose(normals, normals_ref, atol=normal_agreement, err_msg=str(k))
        assert least == gaps[0]
        if {a, b} == {"capsule", "box"}:
            capsule, box = (pose_a, pose_b) if a == "capsule" else (pose_b, pose_a)
            half = OBSTACLE_BOX / 2 if fixed else HALF_A
            assert gaps[0] == pytest.approx(_segment_box_distance(capsule, box, half), abs=SAME), k
    assert answered >= 0.8 * samples, answered  # coal answers only what round-off could decide
    if {a, b} == {"capsule", "box"}:
        assert patches >= 10, patches  # a capsule lying on a face: coal's two points


def _contacts(scene: gaussim.Scene, pose_a: pin.SE3, pose_b: pin.SE3 = ORIGIN):
    """The detector's contacts at these poses, with coal's at its tightest tolerances, and whether the
    compiled pairs answered themselves."""
    detector = ContactDetector(scene, MARGIN)
    (routine,) = detector.routines
    asked = _asking(routine)
    data = scene.robot.model.createData()
    _place(scene, data, pose_a, pose_b)
    contacts = detector.detect(data)
    ((_, points, normals, gaps),) = _tight(detector.pairs, [0]).detect(data, MARGIN, STILL)[0]
    np.testing.assert_allclose(contacts.point, points, atol=SAME)
    np.testing.assert_allclose(contacts.normal, normals, atol=SAME)
    np.testing.assert_allclose(contacts.gap, gaps, atol=SAME)
    return contacts, not asked


@pytest.mark.parametrize("gap", [2e-4, -2e-4])
def test_a_sphere_on_a_sphere_and_on_a_box_face_edge_and_corner(gap):
    """A ball against a ball: it touches at its point towards the other's centre, with their centres'
    distance less both radii; against a box's face, edge and corner (a fixed box at a random pose, or
    a body's box against a fixed ball): at the ball's point towards the feature, the normal along the
    feature's outward direction, at the gap it was placed at; the compiled pairs answer, as coal does."""
    rng = np.random.default_rng(11)
    centre = rng.uniform(-0.1, 0.1, 3)
    apart = rng.normal(size=3)
    apart /= np.linalg.norm(apart)
    other = centre - apart * (2 * SPHERE_RADIUS + gap)
    contacts, answered = _contacts(
        _scene("sphere", "sphere", False), pin.SE3(np.eye(3), centre), pin.SE3(np.eye(3), other)
    )
    assert answered and len(contacts) == 1
    np.testing.assert_allclose(contacts.gap, gap, atol=SAME)
    np.testing.assert_allclose(contacts.normal[0], apart, atol=SAME)
    np.testing.assert_allclose(contacts.point[0], centre - SPHERE_RADIUS * apart, atol=SAME)
    box = pin.SE3(pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3)), rng.uniform(-0.1, 0.1, 3))
    half = OBSTACLE_BOX / 2
    for feature in ([1.0, 0.3, -0.2], [1.0, -1.0, 0.4], [-1.0, 1.0, 1.0]):  # face, edge, corner
        local = np.clip(feature, -1, 1) * half
        outward = np.where(np.abs(feature) == 1, feature, 0.0)
        outward = box.rotation @ (outward / np.linalg.norm(outward))
        surface = box.act(local)
        ball = surface + outward * (SPHERE_RADIUS + gap)
        contacts, answered = _contacts(_scene("sphere", "box", True, box), pin.SE3(np.eye(3), ball))
        assert answered and len(contacts) == 1
        np.testing.assert_allclose(contacts.gap, gap, atol=SAME)
        np.testing.assert_allclose(contacts.normal[0], outward, atol=SAME)
        np.testing.assert_allclose(contacts.point[0], ball - SPHERE_RADIUS * outward, atol=SAME)
        # the box a body's, the ball fixed (OBSTACLE_SPHERE): the point on the box's feature
        ball = surface + outward * (OBSTACLE_SPHERE + gap)
        scene = gaussim.Scene(
            bodies={"a": FreeBody.box("a", tuple(OBSTACLE_BOX), mass=1.0)},
            obstacles=[gaussim.Sphere("b", OBSTACLE_SPHERE, position=ball)],
        )
        contacts, answered = _contacts(scene, box)
        assert answered and len(contacts) == 1
        np.testing.assert_allclose(contacts.gap, gap, atol=SAME)
        np.testing.assert_allclose(contacts.normal[0], -outward, atol=SAME)
        np.testing.assert_allclose(contacts.point[0], surface, atol=SAME)


def _lying(angle: float, centre: np.ndarray) -> pin.SE3:
    """A capsule (along its z) lying horizontally at ``angle`` [rad] from the world's x."""
    return pin.SE3(pin.utils.rotate("z", angle) @ pin.utils.rotate("y", np.pi / 2), centre)


def test_capsules_lying_on_each_other_touch_as_coal_patches_them():
    """Capsule a lying on capsule b (both along x, a shifted along them): coal's single point, below
    a's end at -half length, on the parallel segments coal's patch leaves to one point. Crossed at
    30 degrees one way, one point where they cross; the other way, coal's patch of two points, a's
    ends projected onto b's axis, on a's underside."""
    gap, half = 2e-4, CAPSULE_LENGTH / 2
    height = 2 * CAPSULE_RADIUS + gap
    scene = _scene("capsule", "capsule", False)
    contacts, _ = _contacts(scene, _lying(0.0, np.array([0.01, 0.0, height])), _lying(0.0, np.zeros(3)))
    np.testing.assert_allclose(contacts.point, [[0.01 - half, 0.0, height - CAPSULE_RADIUS]], atol=SAME)
    np.testing.assert_allclose(contacts.normal, [[0.0, 0.0, 1.0]], atol=SAME)
    np.testing.assert_allclose(contacts.gap, [gap], atol=SAME)
    angle = np.radians(30)
    contacts, answered = _contacts(
        scene, _lying(angle, np.array([0.0, 0.0, height])), _lying(0.0, np.zeros(3))
    )
    assert answered
    np.testing.assert_allclose(contacts.point, [[0.0, 0.0, height - CAPSULE_RADIUS]], atol=SAME)
    contacts, answered = _contacts(
        scene, _lying(-angle, np.array([0.0, 0.0, height])), _lying(0.0, np.zeros(3))
    )
    assert answered
    ends = [[x, 0.0, height - CAPSULE_RADIUS] for x in (-half * np.cos(angle), half * np.cos(angle))]
    np.testing.assert_allclose(contacts.point, ends, atol=SAME)
    np.testing.assert_allclose(contacts.normal, np.tile([0.0, 0.0, 1.0], (2, 1)), atol=SAME)
    np.testing.assert_allclose(contacts.gap, [gap, gap], atol=SAME)


def test_a_capsule_lying_on_a_box_touches_at_its_ends_clipped_to_the_face():
    """A capsule lying on a fixed box's top face: its two ends' undersides, at the gap it was placed
    at; hanging over the face's edge, its segment clipped at that edge."""
    gap, half = 2e-4, CAPSULE_LENGTH / 2
    top = OBSTACLE_BOX[2] / 2
    scene = _scene("capsule", "box", True)
    for x, ends in ((0.0, (-half, half)), (0.09, (0.09 - half, OBSTACLE_BOX[0] / 2))):
        contacts, answered = _contacts(scene, _lying(0.0, np.array([x, 0.01, top + CAPSULE_RADIUS + gap])))
        assert answered
        np.testing.assert_allclose(contacts.point, [[e, 0.01, top + gap] for e in ends], atol=SAME)
        np.testing.assert_allclose(contacts.normal, np.tile([0.0, 0.0, 1.0], (2, 1)), atol=SAME)
        np.testing.assert_allclose(contacts.gap, [gap, gap], atol=SAME)


PILE_STEPS = 200


def test_the_bin_pile_steps_as_with_coal(monkeypatch):
    """examples/bin_pile.py's pile (spheres, capsules and boxes in a bin of boxes) for PILE_STEPS
    steps: at every detection of the run with coal answering the primitives' pairs, the compiled pairs
    find the same contacts (names, points, normals, gaps); and the run with the compiled pairs, but a
    capsule's on a box (whose GJK answer coal's box support rounds, see GJK_AGREEMENT), is the same
    run to round-off."""
    setup = bin_pile()
    compiled = ContactDetector(setup.scene, MARGIN)
    routines = dict(driver.ROUTINES)

    def run(skipped: set) -> tuple[np.ndarray, int]:
        monkeypatch.setattr(driver, "ROUTINES", {k: v for k, v in routines.items() if k not in skipped})
        sim = gaussim.Simulator(setup.scene, gaussim.Options(dt=setup.dt))
        reference = sim.detector
        find, compared = reference.find, []

        def checked(data: pin.Data):
            answer = find(data)
            compiled.schedule.margin = reference.schedule.margin
            expected, found = reference.contacts(answer), compiled.detect(data)
            assert found.names == expected.names, (len(compared), set(found.names) ^ set(expected.names))
            np.testing.assert_allclose(found.point, expected.point, atol=GJK_AGREEMENT)
            np.testing.assert_allclose(found.normal, expected.normal, atol=GJK_AGREEMENT)
            np.testing.assert_allclose(found.gap, expected.gap, atol=GJK_AGREEMENT)
            compared.append(len(found))
            return answer

        reference.find = checked  # type: ignore[method-assign]
        state = sim.reset(setup.q, setup.v)
        trajectory = []
        for _ in range(PILE_STEPS):
            state = sim.step(state)
            trajectory.append(state.q)
        return np.array(trajectory), sum(compared)

    new = {key for key, routine in routines.items() if routine is PrimitivePairs}
    with_coal, contacts = run(new)
    assert contacts > 1000  # the pile touches
    capsule_on_box = {(coal.Capsule, coal.Box), (coal.Box, coal.Capsule)}
    compiled_run, _ = run(capsule_on_box)
    np.testing.assert_allclose(compiled_run, with_coal, rtol=0, atol=SAME)


@pytest.mark.parametrize("normal", [(0.0, 0.0, 1.0), (0.2, -0.3, 1.0)])
def test_a_cylinder_on_the_ground_touches_where_coal_says(normal):
    """A cylinder (radius 5 cm, length 20 cm) at random heights within the margin of a (tilted)
    ground, standing on a cap, lying on its side (each within 0 to 0.03 rad) or at any angle: the
    compiled pass gives coal's points (its tightest tolerances: the cap's 12 rim samples, the two ends
    of the side, or the deepest rim point), gaps and normal; coal answers only what round-off could
    decide."""
    from gaussim.collision.cylinders import CAP_SAMPLES, GroundCylinders

    cylinder = FreeBody.cylinder("c", radius=0.05, length=0.2, mass=1.0)
    ground = gaussim.Ground(normal=normal, height=-0.3)
    scene = gaussim.Scene(bodies={"c": cylinder}, ground=ground)
    detector = ContactDetector(scene, MARGIN)
    (routine,) = detector.routines
    assert isinstance(routine, GroundCylinders)
    asked, reference = _asking(routine), _tight(detector.pairs, [0])
    data, n = scene.robot.model.createData(), np.asarray(ground.normal)
    rng, counts, handed = np.random.default_rng(7), {1: 0, 2: 0, CAP_SAMPLES: 0}, 0
    up = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), n).matrix()
    for k in range(300):
        tilt = pin.rpy.rpyToMatrix(*rng.uniform(-1, 1, 3) * [0.0, 1e-6, 1e-3, 3e-2][k % 4])
        kind = k % 3
        if kind == 0:  # on a cap (either)
            R = up @ pin.rpy.rpyToMatrix(np.pi * rng.integers(2), 0, rng.uniform(-np.pi, np.pi)) @ tilt
        elif kind == 1:  # on its side
            R = up @ pin.rpy.rpyToMatrix(np.pi / 2, 0, rng.uniform(-np.pi, np.pi)) @ tilt
        else:
            R = pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3))
        # the centre as high as the deepest point is below it, plus a gap within the margin
        d = R.T @ -n
        reach = 0.05 * np.hypot(d[0], d[1]) + 0.1 * abs(d[2])
        centre = (-0.3 + reach + rng.uniform(-MARGIN, MARGIN)) * n + rng.uniform(-1, 1, 3) * [1, 1, 0]
        _place(scene, data, pin.SE3(R, centre), ORIGIN)
        asked.clear()
        mine, least = routine.detect(data, MARGIN, STILL)
        expected, _ = reference.detect(data, MARGIN, STILL)
        assert len(mine) == len(expected), k
        handed += bool(asked)
        if asked or not mine:
            continue
        (_, points, normals, gaps), (_, points_ref, normals_ref, gaps_ref) = mine[0], expected[0]
        assert points.shape == points_ref.shape, k
        counts[len(points)] += 1
        np.testing.assert_allclose(points, points_ref, atol=AGREEMENT, err_msg=str(k))
        np.testing.assert_allclose(gaps, gaps_ref, atol=AGREEMENT, err_msg=str(k))
        np.testing.assert_allclose(normals, normals_ref, atol=AGREEMENT, err_msg=str(k))
        assert least == gaps[0]
    assert min(counts.values()) >= 20 and handed <= 30, (counts, handed)  # each kind, answered here


def test_a_cylinder_rolls_down_an_incline_as_the_closed_form_says():
    """A solid cylinder (radius 5 cm, length 20 cm) on its side on a 20 degree incline (mu 0.8, above
    tan(20 deg) / 3) rolls without slipping: its centre travels a t^2 / 2 down the slope, a = 2/3 g
    sin(20 deg), and turns by that over its radius; it touches at the two ends of its side, which the
    compiled pass gives."""
    from gaussim.collision.cylinders import GroundCylinders

    angle, r = np.radians(20.0), 0.05
    down = np.array([np.cos(angle), 0.0, -np.sin(angle)])  # along the slope, downhill
    n = np.array([np.sin(angle), 0.0, np.cos(angle)])
    cylinder = FreeBody.cylinder("c", radius=r, length=0.2, mass=1.0)
    scene = gaussim.Scene(bodies={"c": cylinder}, ground=gaussim.Ground(normal=n, friction=0.8))
    sim = gaussim.Simulator(scene, gaussim.Options(dt=1e-3))
    assert [type(routine) for routine in sim.detector.routines] == [GroundCylinders]
    # the axis along y, across the slope; resting on it
    R = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), n).matrix() @ pin.rpy.rpyToMatrix(
        np.pi / 2, 0.0, 0.0
    )
    start = r * n
    state = sim.reset({"c": pin.SE3(R, start)})
    points = []
    for _ in range(500):
        state = sim.step(state)
        points.append(len(sim.last_step.contacts))
    t, a = state.t, 2.0 / 3.0 * 9.81 * np.sin(angle)
    travel = (state.q[:3] - start) @ down
    assert travel == pytest.approx(a * t**2 / 2, rel=5e-3)
    assert abs((state.q[:3] - start) @ n) < 1e-4  # on the slope
    assert np.linalg.norm(state.v[3:6]) * r == pytest.approx(a * t, rel=5e-3)  # rolling: w r = v
    assert min(points) == max(points) == 2

"""Contact detection: the compiled polyhedron-on-ground pass agrees with coal's narrow phase."""

from __future__ import annotations

import gc
from collections.abc import Iterator

import coal
import numpy as np
import pinocchio as pin
import pytest

import gaussim
from gaussim.bench.cases import two_boxes
from gaussim.collision import PATCH_MIN_EXTENT, PATCH_TOLERANCE, ContactDetector, driver
from gaussim.collision.contacts import MAX_POINTS
from gaussim.collision.ground import GroundHulls, touching
from gaussim.collision.narrow import BoundingSpheres, NarrowPhase
from gaussim.collision.primitives import PrimitivePairs
from gaussim.constraints.contact import SLIP_TOLERANCE
from gaussim.kernels.collision import in_pair_order

from .conftest import at_height, run

FEET = ("FL", "FR", "HL", "HR")
# Both compute the same support point in floating point; they may round differently.
AGREEMENT = 1e-9
RADIUS = 0.1  # the ball robot's radius [m]


def _coal_deepest(pair, placement: pin.SE3, margin: float) -> tuple[float, np.ndarray]:
    """coal's signed distance and robot-side nearest point for one pair."""
    request = coal.CollisionRequest()
    request.security_margin = margin
    result = coal.CollisionResult()
    assert coal.collide(pair.shape, placement, pair.obstacle_shape, pair.obstacle_tf, request, result)
    contact = result.getContact(0)
    return contact.penetration_depth, contact.getNearestPoint1().copy()


def _random_poses(robot: gaussim.Robot, count: int, seed: int) -> Iterator[pin.Data]:
    """Data after forward kinematics at ``count`` random configurations of a floating robot."""
    model, data = robot.model, robot.model.createData()
    pin.seed(seed)
    for _ in range(count):
        q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
        q[3:7] /= np.linalg.norm(q[3:7])
        pin.forwardKinematics(model, data, q)
        yield data


@pytest.mark.parametrize("normal", [(0.0, 0.0, 1.0), (0.3, -0.2, 1.0)])
def test_polyhedra_on_ground_match_coal(solo12, normal):
    """Random poses of Solo-12 above a (tilted) ground: a foot touching at one point touches at coal's
    deepest point with coal's gap; a foot touching more widely touches at vertices within
    PATCH_TOLERANCE of that depth."""
    ground = gaussim.Ground(normal=normal, height=-2.0)
    scene = gaussim.Scene(solo12, ground=ground, contacts=[(f"{leg}_FOOT_0", "ground") for leg in FEET])
    margin = 10.0  # every foot is "in contact": all of them are compared
    detector = ContactDetector(scene, margin)
    compared = 0
    for data in _random_poses(solo12, 100, seed=0):
        contacts = detector.detect(data)
        for pair in detector.pairs:
            placement = data.oMi[pair.joint] * pair.local
            gap, point = _coal_deepest(pair, placement, margin)
            mine = [i for i, name in enumerate(contacts.names) if name.startswith(pair.name + "#")]
            assert mine, f"{pair.name} not detected"
            assert gap - AGREEMENT <= contacts.gap[mine].min() <= gap + PATCH_TOLERANCE
            if len(mine) == 1:
                assert contacts.gap[mine[0]] == pytest.approx(gap, abs=AGREEMENT)
                np.testing.assert_allclose(contacts.point[mine[0]], point, atol=AGREEMENT)
                np.testing.assert_allclose(contacts.normal[mine[0]], ground.normal, atol=1e-15)
                compared += 1
    assert compared >= 200, compared  # most random poses touch at one vertex


@pytest.mark.parametrize("normal", [(0.0, 0.0, 1.0), (0.3, -0.2, 1.0)])
def test_a_sphere_on_ground_matches_coal(normal):
    """A sphere is the ball of its radius around a one-vertex hull: random poses above a (tilted)
    ground give coal's gap and nearest point, in the compiled pass (no narrow-phase call)."""
    ball = gaussim.load_robot("ball", floating_base=True)
    ground = gaussim.Ground(normal=normal, height=-2.0)
    detector = ContactDetector(gaussim.Scene(ball, ground=ground), 10.0)
    assert [type(r) for r in detector.routines] == [GroundHulls] and len(detector.routines[0].pairs) == 1
    pair = detector.pairs[0]
    for data in _random_poses(ball, 50, seed=1):
        contacts = detector.detect(data)
        gap, point = _coal_deepest(pair, data.oMi[pair.joint] * pair.local, 10.0)
        assert contacts.gap[0] == pytest.approx(gap, abs=AGREEMENT)
        np.testing.assert_allclose(contacts.point[0], point, atol=AGREEMENT)
        np.testing.assert_allclose(contacts.normal[0], ground.normal, atol=1e-15)


def _outline_reference(heights, world, bound, directions):
    """The outline of the vertices at most ``bound`` above the ground (their ``heights`` and
    ``world`` points), stated plainly: the deepest alone when they span at most PATCH_MIN_EXTENT,
    else the first extreme one along each direction (vertex indices)."""
    near = np.flatnonzero(heights <= bound)
    if np.ptp(world[near], axis=0).max() <= PATCH_MIN_EXTENT:
        return {int(near[np.argmin(heights[near])])}
    return {int(near[np.argmax(world[near] @ d)]) for d in directions}


def test_a_widened_patch_is_the_plain_statement_of_its_outline(solo12):
    """Every Solo-12 mesh hull (287 to 672 vertices, padded to the largest) at random poses above
    the ground, its patch widened by its pair's turn times its diameter (a turning body; each pair its
    own turn): the compiled pass gives, hull by hull,
    the vertices of the plain statement (the extremes along the support directions of the vertices
    within the patch's depth, the resting patch's outline and the deepest), with their gaps."""
    from gaussim.kernels.collision import NARROW_SLACK

    scene = gaussim.Scene(solo12, ground=gaussim.Ground(height=-2.0))
    (routine,) = [r for r in ContactDetector(scene, 10.0).routines if isinstance(r, GroundHulls)]
    hulls = routine.hulls
    assert len(set(hulls.sizes.tolist())) > 1 and hulls.sizes.max() == hulls.columns.shape[2]
    # each declared pair its own turn [rad]: each hull's patch deepens by it times its own diameter;
    # the hulls' pairs numbered from 3 (as among other pairs), so that hull k is not pair k
    index = routine.index + 3
    turns = np.random.default_rng(5).uniform(0.02, 0.2, index.max() + 1)
    widenings, wide = np.maximum(PATCH_TOLERANCE, turns[index] * routine.diameters), 0
    assert np.ptp(widenings) > 0.01 and (widenings == PATCH_TOLERANCE).any()
    for data in _random_poses(solo12, 20, seed=3):
        hulls.narrow_at[:] = np.nan  # no kept verdict: each pose is judged afresh
        placements = routine.placements(data)
        (pairs, points, _, gaps), _ = touching(
            placements, routine.joints, hulls, 10.0, index, turns, routine.diameters
        )
        for k, pair in enumerate(index):
            widening = widenings[k]
            X = hulls.columns[k, :3, : hulls.sizes[k]]  # the hull's own vertices, joint frame
            joint = data.oMi[int(routine.joints[k])]  # Pinocchio's own, not the kernel's view of it
            world = (joint.rotation @ X).T + joint.translation
            heights = world[:, 2] + 2.0
            lowest = heights.min()
            near = X[:, heights <= lowest + widening + NARROW_SLACK]
            if np.ptp(near, axis=1).max() <= PATCH_MIN_EXTENT:
                expected = {int(np.argmin(heights))}
            else:
                wide += 1
                expected = _outline_reference(heights, world, lowest + widening, hulls.directions[k])
                if widening > PATCH_TOLERANCE:  # widened: the resting patch's outline and the deepest too
                    expected |= _outline_reference(
                        heights, world, lowest + PATCH_TOLERANCE, hulls.directions[k]
                    )
                    expected.add(int(np.argmin(heights)))
            got = pairs == pair
            order = sorted(expected)
            np.testing.assert_allclose(points[got], world[order], atol=1e-12)
            np.testing.assert_allclose(gaps[got], heights[order], atol=1e-12)
    assert wide >= 100, wide  # most hulls touch widely


def test_a_rounded_hull_at_the_margin_keeps_its_deepest_vertex():
    """A capsule's segment whose gap equals the margin, at heights where (h - r) + r rounds below h:
    the widened outline still holds the deepest vertex (it picked none, then the padding, before)."""
    from gaussim.kernels.collision import _outline

    rounding, lowest = 0.04689779958975574, 0.11492688060828223
    assert (lowest - rounding) + rounding < lowest  # the case: the bound rounds below the deepest
    X = np.array([[0.0, 1.0], [0.0, 0.0], [lowest, lowest + 1.0], [1.0, 1.0]])  # two vertices, joint frame
    ground = np.array([0.0, 0.0, 1.0, 0.0])  # z = 0, seen from the joint at the origin
    directions = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    order = np.empty(2, np.int64)
    picked = np.full(5, -7, np.int64)
    heights = ground[:3] @ X[:3] + ground[3]
    picks, _ = _outline(
        np.eye(3), np.zeros(3), X, heights, 2, rounding, directions, lowest - rounding,
        (PATCH_TOLERANCE, PATCH_MIN_EXTENT), lowest, order, picked, 0, -1,
    )  # fmt: skip
    assert picked[:picks].tolist() == [0]


def test_box_flat_on_ground_touches_at_its_corners(box):
    """A box resting flat: four corner contacts, each with its own gap; tilted slightly, the same
    four with gaps that differ by the tilt; far above: nothing."""
    scene = gaussim.Scene(box, ground=gaussim.Ground())
    detector = ContactDetector(scene, 1e-3)
    model, data = box.model, box.model.createData()
    half = np.asarray(box.collision_model.geometryObjects[0].geometry.halfSide)
    q = box.neutral()
    q[2] = half[2] + 1e-4
    pin.forwardKinematics(model, data, q)
    contacts = detector.detect(data)
    assert len(contacts) == 4
    np.testing.assert_allclose(contacts.gap, 1e-4, atol=1e-12)
    np.testing.assert_allclose(np.abs(contacts.point[:, :2]), np.tile(half[:2], (4, 1)), atol=1e-12)
    assert np.ptp(contacts.point[:, :2], axis=0).min() > PATCH_MIN_EXTENT
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(2e-4, 0, 0)).coeffs()
    pin.forwardKinematics(model, data, q)
    tilted = detector.detect(data)
    assert len(tilted) == 4
    assert np.ptp(tilted.gap) == pytest.approx(2 * half[1] * np.sin(2e-4), rel=1e-6)
    q[2] = 1.0
    pin.forwardKinematics(model, data, q)
    assert len(detector.detect(data)) == 0


# A 0.2 m box resting on another (top centre, then bottom, as free-flyer configurations) where coal
# 3.0's default GJK/EPA gives a NaN normal and a depth of -DBL_MAX (found by a mass-ratio stack run).
_FACE_TO_FACE = [
    "-0x1.c999b3713edf3p-42", "-0x1.8074963e13735p-41", "0x1.999999999a35bp-4", "0x1.7939019f74e3ep-45",
    "0x1.279c7c2271ecfp-44", "-0x1.28009baccf4d5p-54", "0x1.0000000000000p+0", "-0x1.6755948f5ac47p-40",
    "-0x1.990d15169bd92p-40", "0x1.333333335fa19p-2", "0x1.1b4372fc8f449p-38", "-0x1.82544727ead60p-41",
    "0x1.ac376a0b98393p-49", "0x1.0000000000000p+0",
]  # fmt: skip


def test_box_on_box_face_to_face_gives_a_finite_contact(tmp_path):
    """The pose coal's default GJK fails on gives a finite contact (the retry's answer)."""
    robot = two_boxes(tmp_path / "pair.urdf", 1.0, 100.0)
    scene = gaussim.Scene(robot, ground=gaussim.Ground(), contacts=[("top_0", "bottom_0")])
    q = np.array([float.fromhex(x) for x in _FACE_TO_FACE])
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    contacts = ContactDetector(scene, 1e-3).detect(data)
    assert np.isfinite(contacts.normal).all() and np.isfinite(contacts.gap).all()
    assert np.allclose(contacts.normal, [0.0, 0.0, 1.0], atol=1e-9)  # the bottom box's top face
    assert np.all(np.abs(contacts.gap) < 1e-9)


def _sphere(shape: coal.CollisionGeometry, placement: pin.SE3) -> tuple[np.ndarray, float]:
    """The world centre and radius of coal's bounding sphere of ``shape`` at ``placement``."""
    shape = shape.convex if isinstance(shape, coal.BVHModelBase) else shape
    shape.computeLocalAABB()
    return placement.act(np.asarray(shape.aabb_center)), shape.aabb_radius


@pytest.mark.parametrize("interleaved", [True, False])
def test_the_points_of_several_routines_come_in_the_declared_order_of_their_pairs(interleaved):
    """The routines' pieces, concatenated, end up in numpy's stable sort by declared pair: each
    pair's points in the order its routine gave them, whether the routines' pairs interleave (as a
    box on the ground, on a box, on the ground does: pairs 0 and 2 from one routine, 1 from another)
    or not. Three routines of 60 to 90 points on 12 pairs (a sort that is not stable fails here)."""
    rng = np.random.default_rng(3)
    pairs = rng.permutation(12) if interleaved else np.arange(12)
    pieces = [
        np.sort(rng.choice(pairs[r::3] if interleaved else pairs[4 * r : 4 * r + 4], 60 + 15 * r))
        for r in range(3)
    ]
    owner = np.concatenate(pieces).astype(np.int64)
    points, normals, gaps = (
        rng.normal(size=(len(owner), 3)),
        rng.normal(size=(len(owner), 3)),
        rng.normal(size=len(owner)),
    )
    order = np.argsort(owner, kind="stable")
    expected = owner[order], points[order], normals[order], gaps[order]
    found = owner.copy(), points.copy(), normals.copy(), gaps.copy()
    in_pair_order(*found)
    for got, want in zip(found, expected, strict=True):
        np.testing.assert_array_equal(got, want)


def test_a_contact_keeps_its_key_and_its_rows_their_ids_from_step_to_step():
    """Each point's key is its declared pair and its rank among that pair's points, whichever pairs
    touch: two boxes resting on the ground (pairs 0 and 1) keep keys 0..3 and MAX_POINTS + 0..3 and
    their rows the same ids, step after step; with the first box lifted away, the second box's points
    keep theirs (the rows' places move up by the first box's rows, their ids do not)."""
    boxes = {f"box{k}": gaussim.FreeBody.box(f"box{k}", (0.1, 0.1, 0.1), mass=1.0) for k in range(2)}
    scene = gaussim.Scene(bodies=boxes, ground=gaussim.Ground(friction=0.5))
    sim = gaussim.Simulator(scene)
    resting = {name: gaussim.pose(0.5 * k, 0, 0.05) for k, name in enumerate(boxes)}
    state = sim.reset(resting)
    keys, ids = [], []
    for _ in range(3):
        state = sim.step(state)
        (_, rows, _), *_ = sim.last_step.blocks
        keys.append(rows.data.contacts.key.tolist())
        ids.append(rows.ids().tolist())
    second = [MAX_POINTS + k for k in range(4)]
    assert keys == [[0, 1, 2, 3, *second]] * 3
    assert ids[0] == ids[1] == ids[2] and len(set(ids[0])) == 8 * 4  # four facets a point
    state = sim.reset({"box0": gaussim.pose(0, 0, 1.0), "box1": resting["box1"]})
    state = sim.step(state)
    (_, rows, _), *_ = sim.last_step.blocks
    assert rows.data.contacts.key.tolist() == second
    assert rows.ids().tolist() == ids[0][16:]


def test_point_keys_are_each_points_pair_and_rank_among_its_pairs_points():
    """The compiled keys against their statement, counted point by point: pair * MAX_POINTS + rank,
    the rank capped at MAX_POINTS - 1 (a pair with more points), and each pair's first point and count."""
    from gaussim.kernels.pairs import point_keys

    owner = np.array([0, 0, 0, 3, 5, 5] + [7] * (MAX_POINTS + 2) + [9], dtype=np.int64)
    keys = np.empty(len(owner), np.int64)
    starts, counts = point_keys(owner, MAX_POINTS, keys)
    ranks = [sum(1 for earlier in owner[:i] if earlier == pair) for i, pair in enumerate(owner.tolist())]
    assert keys.tolist() == [p * MAX_POINTS + min(r, MAX_POINTS - 1) for p, r in zip(owner.tolist(), ranks)]
    assert starts.tolist() == [0, 3, 4, 6, 8 + MAX_POINTS]
    assert counts.tolist() == [3, 1, 2, MAX_POINTS + 2, 1]


def test_the_broad_phase_bounds_every_gap_and_sends_only_near_pairs_to_coal(monkeypatch):
    """Free objects of every shape, a pendulum's bob (off its joint) and a table at random poses: the
    broad phase's gaps are the bounding spheres' at Pinocchio's geometry placements, and within the
    margin at least the larger of that and coal's distance from the robot geometry's sphere to the
    obstacle's bounding box (more where the geometry's vertices are farther from that box); never more
    than coal's distance of the shapes, and coal sees exactly the pairs within the margin (and every
    pair with the ground)."""
    shapes = [
        gaussim.FreeBody.box("box", (0.2, 0.1, 0.05), mass=1.0),
        gaussim.FreeBody.sphere("ball", 0.06, mass=1.0),
        gaussim.FreeBody.capsule("capsule", 0.03, 0.15, mass=1.0),
        gaussim.FreeBody.cylinder("can", 0.05, 0.1, mass=1.0),
    ]
    turned = pin.rpy.rpyToMatrix(0.3, 0.2, 0.5)  # a table's box turned: its axes are not the world's
    table = gaussim.Box("table", size=(0.3, 0.3, 0.1), position=(0.2, 0.0, 0.05), rotation=turned)
    bodies: dict[str, object] = {body.name: body for body in shapes}
    bodies["pendulum"] = gaussim.Body(gaussim.load_robot("pendulum"), placement=gaussim.pose(z=1.1))
    scene = gaussim.Scene(bodies=bodies, ground=gaussim.Ground(), obstacles=[table])
    margin = 0.05
    # the primitives' pairs go to coal too: the broad phase in front of coal is what is tested
    monkeypatch.setattr(
        driver, "ROUTINES", {k: v for k, v in driver.ROUTINES.items() if v is not PrimitivePairs}
    )
    detector = ContactDetector(scene, margin)
    (narrow,) = [r for r in detector.routines if isinstance(r, NarrowPhase)]
    spheres_only = BoundingSpheres(narrow.pairs)  # the spheres and the box, without the vertices
    robot, rng = scene.robot, np.random.default_rng(4)
    model, data, geometry_data = robot.model, robot.model.createData(), robot.collision_model.createData()
    collide, seen = NarrowPhase.collide, []

    def counted(self, pair, data):
        seen.append(pair.name)
        return collide(self, pair, data)

    monkeypatch.setattr(NarrowPhase, "collide", counted)
    compared = near = boxed = tightened = 0
    for _ in range(200):
        q = robot.neutral()
        for layout in scene.bodies.values():
            part = q[layout.q]
            if not layout.floating:  # the pendulum, swinging through the objects
                part[:] = rng.uniform(-0.6, 0.6, len(part))
                continue
            part[:3] = rng.uniform((-0.3, -0.3, 0.0), (0.3, 0.3, 0.4))
            part[3:7] = pin.Quaternion(*rng.normal(size=4)).normalized().coeffs()
        pin.updateGeometryPlacements(model, data, robot.collision_model, geometry_data, q)
        seen.clear()
        detector.detect(data)
        apart, plain = narrow.spheres.gaps(data, margin), spheres_only.gaps(data, margin)
        for pair, gap, sphere_gap in zip(narrow.pairs, apart, plain):
            if pair.obstacle_radius == np.inf:  # the ground: coal's half-space test
                assert gap == -np.inf and pair.name in seen
                continue
            a = robot.collision_model.getGeometryId(pair.geometry)
            center, radius = _sphere(pair.shape, geometry_data.oMg[a])
            if pair.other_local is None:
                placement, other_shape = table.placement(), table.shape()
            else:
                b = robot.collision_model.getGeometryId(pair.obstacle_name)
                placement, other_shape = geometry_data.oMg[b], pair.obstacle_shape
            other_center, other_radius = _sphere(other_shape, placement)
            spheres = np.linalg.norm(center - other_center) - radius - other_radius
            to_box = _to_box(center, radius, other_shape, placement)
            if spheres > margin or to_box <= 0.0:  # a sphere inside the box: the kernel's is -radius
                ok = sphere_gap == pytest.approx(spheres, abs=1e-12)
                assert ok or (spheres <= margin and sphere_gap <= 0.0)
            else:
                assert sphere_gap == pytest.approx(max(spheres, to_box), abs=1e-9)
                boxed += to_box > spheres
            assert gap >= sphere_gap and (spheres <= margin or gap == sphere_gap)  # the vertices': within
            tightened += gap > sphere_gap
            result = coal.DistanceResult()
            distance = coal.distance(
                pair.shape,
                coal.Transform3s(geometry_data.oMg[a]),
                pair.obstacle_shape,
                coal.Transform3s(placement),
                coal.DistanceRequest(),
                result,
            )
            if distance > 0:
                assert gap <= distance + AGREEMENT  # the vertices bound it tightly: coal rounds otherwise
                compared += 1
            assert (pair.name in seen) == (gap <= margin)
            near += gap <= margin
    assert compared > 1000 and 100 < near < compared and boxed > 50, (compared, near, boxed)
    assert tightened > 50, tightened


def _to_box(center: np.ndarray, radius: float, shape: coal.CollisionGeometry, placement: pin.SE3) -> float:
    """coal's distance from the sphere (``center``, ``radius``) to the bounding box of ``shape`` (its
    AABB in its own frame) at ``placement``."""
    shape = shape.convex if isinstance(shape, coal.BVHModelBase) else shape
    box = shape.aabb_local
    size = np.asarray(box.max_) - np.asarray(box.min_)
    where = pin.SE3(placement.rotation, placement.act(np.asarray(shape.aabb_center)))
    result = coal.DistanceResult()
    sphere = coal.Transform3s(np.eye(3), center)
    return coal.distance(
        coal.Sphere(radius), sphere, coal.Box(*size), coal.Transform3s(where), coal.DistanceRequest(), result
    )


def _checking_skips(detector: ContactDetector, data: pin.Data) -> list[bool]:
    """Make ``detector`` check each detection the step skips by one at the same placements (``data``,
    the step's: it must find nothing); returns a list that gets True for each skipped detection and
    False for each other."""
    looks: list[bool] = []
    cover = detector.cover

    def checked(*args):
        needed = cover(*args)
        looks.append(not needed)
        if not needed:
            clearance = detector.schedule.clearance
            assert len(detector.detect(data)) == 0, "a skipped detection hid a contact"
            detector.schedule.clearance = clearance  # the skipping goes on as it would have
        return needed

    detector.cover = checked  # type: ignore[method-assign]
    return looks


def _skipping_run(
    scene: gaussim.Scene, q0: np.ndarray, v0: np.ndarray, steps: int, tau=None, scheme: str = "velocity"
) -> tuple[list[bool], set[str]]:
    """Run ``scene`` from (q0, v0), checking every skipped detection (see _checking_skips); the run must
    land. Returns which detections were skipped, and the obstacles touched."""
    sim = gaussim.Simulator(scene, gaussim.Options(scheme=scheme))
    looks = _checking_skips(sim.detector, sim.data)
    state, touched, obstacles = sim.reset(q0, v0), 0, set()
    for _ in range(steps):
        state = sim.step(state, tau)
        touched += bool(sim.last_step.contacts)
        obstacles |= {c.obstacle for c in sim.last_step.contacts}
    assert touched > steps // 4, "the run must land and stay in contact"
    return looks, obstacles


@pytest.mark.parametrize("scheme", ["velocity", "acceleration"])
def test_skipped_detections_hide_no_contact(solo12, scheme):
    """Solo-12 thrown spinning from 0.3 m onto the ground: the flight skips most detections, and a full
    detection at each skipped one finds nothing."""
    feet = [(f"{leg}_FOOT_0", "ground") for leg in FEET]
    scene = gaussim.Scene(solo12, ground=gaussim.Ground(friction=0.8), contacts=feet)
    q0 = solo12.configuration("standing")
    q0[2] += 0.3
    v0 = np.zeros(solo12.model.nv)
    v0[[0, 2, 3, 5]] = 0.5, 1.0, 2.0, 3.0  # sideways and up, rolling and turning
    looks, _ = _skipping_run(scene, q0, v0, 700, np.zeros(12), scheme)
    assert sum(looks) > 250, sum(looks)  # about 0.4 s of flight


def test_skipped_detections_see_an_obstacle_and_the_ground(ball):
    """A ball thrown onto a table (coal's narrow phase, a bounding-sphere bound) rolls off onto the
    ground (the compiled pass): the skipped detections hide no contact."""
    table = gaussim.Box("table", size=(0.4, 0.4, 0.3), position=(0, 0, 0.15))
    scene = gaussim.Scene(ball, ground=gaussim.Ground(), obstacles=[table])
    q0, v0 = at_height(ball, 0.8), np.zeros(ball.model.nv)
    q0[0], v0[0] = -0.3, 0.8
    looks, obstacles = _skipping_run(scene, q0, v0, 1200)
    assert sum(looks) > 200, sum(looks)
    assert obstacles == {"table", "ground"}


def test_a_state_from_elsewhere_is_detected_afresh(ball):
    """After steps in flight (whose detections are skipped) a state given on the ground gets its
    contact at once: the detector forgets what the flight let it skip."""
    sim = gaussim.Simulator(gaussim.Scene(ball, ground=gaussim.Ground()))
    state = run(sim, sim.reset(at_height(ball, 5.0)), 20)
    assert not sim.last_step.contacts and sim.detector.schedule.clearance > 4.0
    landed = gaussim.State(state.t, at_height(ball, RADIUS - 1e-4), np.zeros(ball.model.nv))
    sim.step(landed)
    assert len(sim.last_step.contacts) == 1 and sim.last_step.contacts[0].normal_force > 0


def test_detect_always_looks(box):
    """Only the step skips detections (through cover): detect itself, after a pose far above the
    ground, finds the contacts of a pose on it."""
    detector = ContactDetector(gaussim.Scene(box, ground=gaussim.Ground()), 1e-3)
    model, data = box.model, box.model.createData()
    q = box.neutral()
    q[2] = 5.0
    pin.forwardKinematics(model, data, q)
    assert len(detector.detect(data)) == 0 and detector.schedule.clearance > 4.0
    q[2] = float(np.asarray(box.collision_model.geometryObjects[0].geometry.halfSide)[2])
    pin.forwardKinematics(model, data, q)
    assert len(detector.detect(data)) == 4


def test_the_reach_of_the_free_motion_bounds_the_travel(solo12):
    """In flight the step takes off the clearance the coarse bound dt * reach * the longest lever, with
    reach = sum |v| + |x_free| from the free motion's kernel: never less than the exact travel of any
    pair; near the ground (clearance within twice that of the base margin) the exact one."""
    feet = [(f"{leg}_FOOT_0", "ground") for leg in FEET]
    sim = gaussim.Simulator(gaussim.Scene(solo12, ground=gaussim.Ground(), contacts=feet))
    coarse, exact = (ContactDetector(sim.scene, sim.options.contact_margin).schedule for _ in range(2))
    rng, dt, q = np.random.default_rng(3), sim.options.dt, solo12.configuration("standing")
    for _ in range(50):
        v = rng.normal(size=solo12.model.nv)
        sim.dynamics.free_motion(q, v, np.zeros(18), dt)  # the first call poses the problem; then ABA
        x = sim.dynamics.free_motion(q, v, np.r_[np.zeros(6), rng.normal(size=12)], dt)
        reach = sim.dynamics.reach
        assert reach == pytest.approx(np.abs(v).sum() + np.abs(x).sum(), rel=1e-12)
        for clearance, same in ((100.0, False), (coarse.base_margin + 1e-3, True)):
            coarse.clearance = exact.clearance = clearance
            assert coarse.cover(v, x, dt, 1.0, reach) == exact.cover(v, x, dt, 1.0)
            travel = clearance - exact.clearance
            assert clearance - coarse.clearance == (
                travel if same else pytest.approx(dt * coarse.longest * reach)
            )
            assert clearance - coarse.clearance >= travel > 0


def test_the_travel_bound_holds_for_every_pair_of_a_world(solo12):
    """A world of a robot and three free boxes, each pair of them declared: the travel the margin
    schedule takes off the clearance (its levers kept per pair on that pair's coordinates only) is the
    dense bound max_k dt sum_i levers[k, i] |v_i| over all coordinates, and no pair's bounding spheres
    close by more than it in a step of random motion, nor their gaps to the obstacles' boxes."""
    from gaussim.collision.margin import _pair_levers

    boxes = {f"box{k}": gaussim.FreeBody.box(f"box{k}", (0.1, 0.2, 0.3), mass=1.0) for k in range(3)}
    scene = gaussim.Scene(bodies={"solo": solo12, **boxes}, ground=gaussim.Ground())
    sim = gaussim.Simulator(scene)
    detector = ContactDetector(scene, sim.options.contact_margin)
    spheres = BoundingSpheres(detector.pairs)
    dense = np.array([_pair_levers(sim.model, pair) for pair in detector.pairs])
    rng, dt = np.random.default_rng(7), 1e-3
    starts = {name: gaussim.pose(0.5 * k + 1.0, 0.0, 0.5) for k, name in enumerate(boxes)}
    q = sim.reset({"solo": solo12.configuration("standing"), **starts}).q
    data = sim.model.createData()
    for _ in range(20):
        v = rng.normal(size=sim.model.nv)
        schedule = detector.schedule
        schedule.clearance = 1.0
        schedule.cover(v, v, dt, 0.0)
        travel = 1.0 - schedule.clearance
        assert travel == pytest.approx(dt * (dense @ np.abs(v)).max(), rel=1e-12)
        pin.forwardKinematics(sim.model, data, q)
        before = spheres.gaps(data, np.inf)  # the box gaps too
        pin.forwardKinematics(sim.model, data, pin.integrate(sim.model, q, dt * v))
        closed = before - spheres.gaps(data, np.inf)
        finite = np.isfinite(closed)
        assert finite.sum() > 10 and closed[finite].max() <= travel


def _world_of_solo_and_boxes(solo12: gaussim.Robot) -> tuple[gaussim.Simulator, np.ndarray]:
    """Solo-12 and two free boxes (every pair declared), and a configuration of the three."""
    boxes = {f"box{k}": gaussim.FreeBody.box(f"box{k}", (0.1, 0.2, 0.3), mass=1.0) for k in range(2)}
    sim = gaussim.Simulator(gaussim.Scene(bodies={"solo": solo12, **boxes}, ground=gaussim.Ground()))
    starts = {name: gaussim.pose(0.5 * k + 1.0, 0.2, 0.5) for k, name in enumerate(boxes)}
    return sim, sim.reset({"solo": solo12.configuration("standing"), **starts}).q


def _point(model: pin.Model, q: np.ndarray, joint: int, local: np.ndarray) -> np.ndarray:
    """Where the point ``local`` of ``joint``'s frame (the world's for joint 0) is at q."""
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    return data.oMi[joint].act(local)


def test_how_far_a_contact_point_closes_is_its_speed_by_finite_differences(solo12):
    """The closing kernel's dt (c(v) + c(x_scale x)), c(w) = max(0, mu |u_t(w)| - n . u(w)), for points
    of a leg on the ground, of a box on a leg, of a foot on its own knee (a shared chain): u by
    central differences of Pinocchio's placements of the two sides' points along v and x."""
    from gaussim.dynamics import Supports, joint_jacobians
    from gaussim.kernels.collision import closing

    sim, q = _world_of_solo_and_boxes(solo12)
    model, data = sim.model, sim.model.createData()
    pin.computeJointJacobians(model, data, q)
    foot, knee = model.getJointId("solo/FL_KFE"), model.getJointId("solo/FL_HFE")
    box, hip = model.getJointId("box0/root_joint"), model.getJointId("solo/HR_HAA")
    joints, others = np.array([foot, box, foot, hip, box]), np.array([0, foot, knee, 0, 0])
    rng, dt, eps = np.random.default_rng(11), 1e-3, 1e-6
    points = rng.normal(scale=0.3, size=(len(joints), 3)) + data.oMi[1].translation
    normals = rng.normal(size=(len(joints), 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    mu = np.array([0.0, 0.5, 1.0, 0.8, 0.3])
    for x_scale in (1.0, dt):
        v, x = rng.normal(size=(2, model.nv))
        far = np.full(len(joints), np.nan)
        jacobians, supports = joint_jacobians(data), Supports.of(model)
        closing(jacobians, *supports, joints, others, points, normals, mu, v, x, dt, x_scale, far)
        for i, (a, b) in enumerate(zip(joints.tolist(), others.tolist())):
            local_a, local_b = data.oMi[a].actInv(points[i]), data.oMi[b].actInv(points[i])
            expected = 0.0
            for w in (v, x_scale * x):
                ahead, behind = pin.integrate(model, q, eps * w), pin.integrate(model, q, -eps * w)
                apart = [_point(model, c, a, local_a) - _point(model, c, b, local_b) for c in (ahead, behind)]
                u = (apart[0] - apart[1]) / (2 * eps)
                along = normals[i] @ u
                expected += dt * max(0.0, mu[i] * np.linalg.norm(u - along * normals[i]) - along)
            assert far[i] == pytest.approx(expected, rel=1e-6, abs=1e-12), (i, x_scale)
        assert np.count_nonzero(far) >= 3  # some points close, on each kind of pair


def _keeping_every_point(sim: gaussim.Simulator) -> gaussim.Simulator:
    """``sim`` with every contact point the margin finds kept."""
    sim.detector.beyond_rest = lambda found: False  # type: ignore[method-assign]
    return sim


def _same_steps(
    scene: gaussim.Scene, start: gaussim.State, steps: int, dt: float = 1e-3
) -> tuple[int, int, int]:
    """Step ``scene`` from ``start`` with a simulator that leaves out the points a fast step cannot
    close, and at each state a simulator that keeps them all: the same v+ every step, to the friction
    iteration's tolerance (the two pose different QPs, whose De Saxce passes stop at different points
    within SLIP_TOLERANCE of the fixed point; most steps agree to round-off). Returns the
    points the first kept and the second found over the run, and how many steps the first solved
    again because its answer reached a point it had left out."""
    options = gaussim.Options(dt=dt)
    narrowed, full = (
        gaussim.Simulator(scene, options),
        _keeping_every_point(gaussim.Simulator(scene, options)),
    )
    again, solve_again = [0], narrowed._again

    def counted(*args):
        again[0] += 1
        return solve_again(*args)

    narrowed._again = counted  # type: ignore[method-assign]
    state, kept, found = narrowed.reset(start.q, start.v), 0, 0
    for _ in range(steps):
        given = state
        state = narrowed.step(given)
        alike = full.step(given)
        scale = SLIP_TOLERANCE["accurate"] * max(1.0, np.abs(alike.v).max())
        np.testing.assert_allclose(state.v, alike.v, atol=scale)
        np.testing.assert_allclose(state.q, alike.q, atol=dt * scale)
        kept, found = kept + len(narrowed.last_step.contacts), found + len(full.last_step.contacts)
    return kept, found, again[0]


def test_points_a_fast_step_cannot_close_are_left_out_and_change_no_step(solo12):
    """Solo-12 (every collision geometry) thrown spinning onto the ground at 12 m/s (a step closes
    more than the base margin), its joints flailing: the margin widens to the fastest pair's travel,
    and the points that cannot close within the step (their own speed, at v and at the free motion)
    are left out. A simulator that keeps them all, stepped from each state of the run, finds the same
    v+ with more than twice the points. (The velocity scheme's: the acceleration scheme's impacts
    change v within the step, so it keeps every point, as a test below checks.)"""
    scene = gaussim.Scene(solo12, ground=gaussim.Ground(friction=0.8))
    q0 = solo12.configuration("standing")
    q0[2] += 0.15
    v0 = np.random.default_rng(2).normal(scale=8.0, size=solo12.model.nv)
    v0[:6] = 0.5, 0.0, -12.0, 3.0, -2.0, 1.0
    kept, found, again = _same_steps(scene, gaussim.State(0.0, q0, v0), 150)
    assert found > 2 * kept and again == 0, (kept, found, again)  # none it left out came back


def test_a_point_left_out_that_the_answer_reaches_is_solved_with():
    """A 1 m bar lands on one end while its other end, 10 mm up, rises (dt 10 ms), beside two boxes
    20 mm above the ground: the bar's far end and the boxes are out of reach at v and at the free
    motion, and left out, but the landing end's push swings the far end down within the step: its
    rows fail at v+, and the step is solved again with every point (found by a helper's review: v+
    was 1 m/s off, and 10 mm deep the step after). Tumbling boxes dropped at 5 to 20 ms steps: the
    same v+ as keeping every point."""
    bar = gaussim.FreeBody.box("bar", (1.0, 0.1, 0.05), mass=1.0)
    waiting = {f"box{k}": gaussim.FreeBody.box(f"box{k}", (0.1, 0.1, 0.1), mass=1.0) for k in range(2)}
    scene = gaussim.Scene(bodies={"bar": bar, **waiting}, ground=gaussim.Ground(friction=0.5))
    tilt = np.arcsin(0.009)  # one end 1 mm up, the other 10 mm
    height = 0.001 + 0.5 * np.sin(tilt) + 0.025 * np.cos(tilt)
    poses = {"bar": gaussim.pose(0, 0, height, rpy=(0, tilt, 0))}
    poses |= {name: gaussim.pose(4 * k - 2, 0, 0.07) for k, name in enumerate(waiting)}
    start = gaussim.Simulator(scene).reset(poses, {"bar": [0, 0, -2.0, 0, 4.4, 0]})
    _, _, again = _same_steps(scene, start, 3, dt=0.01)
    assert again >= 1
    box = gaussim.FreeBody.box("box", (0.4, 0.1, 0.1), mass=1.0)
    scene = gaussim.Scene(bodies={"box": box}, ground=gaussim.Ground(friction=0.8))
    rng = np.random.default_rng(0)
    for dt in (0.005, 0.01, 0.02):
        for _ in range(3):
            turned = pin.Quaternion(pin.exp3(rng.normal(size=3))).coeffs()
            twist = np.r_[rng.normal(size=2), -1.0, rng.normal(scale=6, size=3)]
            start = gaussim.Simulator(scene).reset(
                {"box": gaussim.pose(0, 0, 0.4, quaternion=turned)}, {"box": twist}
            )
            _same_steps(scene, start, int(0.6 / dt), dt)


def test_the_acceleration_scheme_keeps_every_point_the_margin_finds(solo12):
    """Its impacts change v within the step, so it leaves no point out: a fast landing never asks."""

    def refused(*args):
        raise AssertionError("the acceleration scheme left points out")

    scene = gaussim.Scene(solo12, ground=gaussim.Ground(friction=0.8))
    sim = gaussim.Simulator(scene, gaussim.Options(scheme="acceleration"))
    sim.detector.reachable = refused  # type: ignore[method-assign]
    q0 = solo12.configuration("standing")
    q0[2] += 0.05
    v0 = np.zeros(solo12.model.nv)
    v0[2] = -12.0
    state, fast = sim.reset(q0, v0), 0
    for _ in range(20):
        state = sim.step(state)
        fast += bool(sim.last_step.contacts) and sim.detector.fast
    assert fast > 3, fast


def test_the_kernels_read_the_joint_placements_where_pinocchio_keeps_them(solo12, monkeypatch):
    """JointPlacements is a read-only view of data.oMi's memory: after every kinematics pass on that data
    it holds Pinocchio's placements (each joint's rotation columns, then its translation), and it keeps
    that data alive; a data of a smaller model is refused. Where a Pinocchio lays them out otherwise it
    copies them: a pile settling (boxes, balls and capsules on each other, a fixed box and the ground)
    runs the same through the copies, bit for bit."""
    from gaussim.bench.scenes import SCENES
    from gaussim.collision import pairs

    placements = pairs.JointPlacements(solo12.model.njoints)
    for data in _random_poses(solo12, 5, seed=11):
        view = placements(data)
        assert not view.flags.writeable and view.shape == (solo12.model.njoints, 4, 3)
        for j, M in enumerate(data.oMi):
            np.testing.assert_array_equal(view[j, :3].T, M.rotation)
            np.testing.assert_array_equal(view[j, 3], M.translation)
        pin.forwardKinematics(
            solo12.model, data, pin.randomConfiguration(solo12.model, -np.ones(19), np.ones(19))
        )
        np.testing.assert_array_equal(view[5, 3], data.oMi[5].translation)  # the same view follows the pass
    # the view holds its data: a view kept after the placements moved to another data still reads it
    kept, held = view, pairs.copied(data.oMi)
    del data, view, M
    placements(solo12.model.createData())
    gc.collect()
    _ = [np.full(4000, 7.0) for _ in range(300)]  # memory a freed data would have gone to
    np.testing.assert_array_equal(kept, held)
    # a data of a model with fewer joints than the pairs read is refused, not read out of bounds
    with pytest.raises(ValueError, match="joint placements"):
        placements(gaussim.load_robot("ur5").model.createData())

    def trajectory() -> np.ndarray:
        setup = SCENES["bin_pile"].build()
        sim = gaussim.Simulator(setup.scene)
        state, qs = sim.reset(setup.q, setup.v), []
        for _ in range(300):
            state = sim.step(state)
            qs.append(state.q)
        assert len(sim.last_step.contacts) > 20
        return np.array(qs)

    viewed = trajectory()
    monkeypatch.setattr(pairs, "_view", lambda data: None)
    np.testing.assert_array_equal(trajectory(), viewed)


def test_the_vertices_bound_each_pair_with_a_box_from_below(monkeypatch):
    """The pairs that go to coal, each against a box (a table-mounted Panda's mesh hulls and finger
    boxes, and a cube, against the table, at random arm configurations and cube poses): within the
    margin, the broad phase bounds a pair's gap by its geometry's vertices along the box's axes, which
    is never more than coal's distance (its tightest GJK) where they are apart, and spares coal the
    pairs a link's loose sphere brought within the margin. The arm's motion is unchanged, bit for bit,
    with the bound off."""
    from gaussim.bench.scenes import SCENES
    from gaussim.collision import narrow

    setup = SCENES["panda_cube"].build()
    scene, model = setup.scene, setup.scene.robot.model
    routine = NarrowPhase(ContactDetector(scene, 0.05).pairs, list(range(len(scene.pairs))))
    table = [i for i, pair in enumerate(routine.pairs) if pair.obstacle_name == "table"]
    assert len(table) >= 10
    spheres_only = narrow.BoundingSpheres(routine.pairs)
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    request.gjk_tolerance = 1e-12
    data, rng, margin, spared = model.createData(), np.random.default_rng(8), 0.05, 0
    for _ in range(40):
        q = setup.q.copy()
        q[:7] += rng.uniform(-1.0, 1.0, 7)  # the arm's joints
        q[9:12] = setup.q[9:12] + rng.uniform([-0.2, -0.2, -0.01], [0.2, 0.2, 0.05])  # the cube
        pin.forwardKinematics(model, data, q)
        bound, loose = routine.spheres.gaps(data, margin), spheres_only.gaps(data, margin)
        for i in table:
            pair = routine.pairs[i]
            placement = data.oMi[pair.joint] * pair.local
            result.clear()
            distance = coal.distance(
                pair.shape, placement, pair.obstacle_shape, pair.obstacle_tf, request, result
            )
            # a lower bound on the distance (deeper overlaps than a bound's are coal's to measure)
            assert bound[i] <= max(distance, 0.0) + 1e-9, (pair.name, bound[i], distance)
            assert bound[i] >= loose[i]
            spared += bool(loose[i] <= margin < bound[i])
    assert spared >= 15, spared

    def run() -> np.ndarray:
        sim = gaussim.Simulator(scene)
        state, qs = sim.reset(setup.q, setup.v), []
        for _ in range(300):
            state = sim.step(state, setup.drive(state.t, state.q, state.v), setup.damping)
            qs.append(state.q)
        return np.array(qs)

    bounded = run()
    monkeypatch.setattr(narrow.support_gaps, "call", lambda *args: None)
    np.testing.assert_array_equal(run(), bounded)

"""Stage 1, dynamics and kinematics (Pinocchio): the free motion, M(q), the joint Jacobians, drifts."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from .exceptions import InvalidState, SolverError
from .kernels.bound import Bound
from .kernels.dynamics import mirrored

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
armed = Bound("dynamics.armed")
constant_terms = Bound("dynamics.constant_terms")
factored_terms = Bound("dynamics.factored_terms")
floating_terms = Bound("dynamics.floating_terms")
frame_accelerations = Bound("dynamics.frame_accelerations")
free_velocity = Bound("dynamics.free_velocity")
loaded = Bound("dynamics.loaded")
negated_product = Bound("dynamics.negated_product")
point_jacobians_into = Bound("dynamics.point_jacobians_into")
structured_product = Bound("dynamics.structured_product")
structured_solve = Bound("dynamics.structured_solve")
structured_terms = Bound("dynamics.structured_terms")
unloaded = Bound("dynamics.unloaded")

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
_WORLD = pin.Convention.WORLD
_IDENTITY = np.eye(3)
# From this many velocity coordinates (a world of free bodies: from one) the step works on M's joint
# structure (MassStructure): Pinocchio's Python crba mirrors and copies all of M and its Cholesky copies
# it again, O(nv^2).
STRUCTURED_NV = 48


@dataclass
class Dynamics:
    """The unconstrained Gauss problem of one level at the current (q, v):

        min_x 1/2 x^T M x + g^T x,   solved by   x_free = -M^-1 g.

    Attributes:
        M: joint-space inertia, shape (nv, nv), symmetric positive definite: a copy of data.M, or a
            :class:`MassStructure`'s buffer, which the next step overwrites.
        g: linear term -M x_free, shape (nv,): -(M v + dt F) at the velocity level (x = v+), -F at the
            acceleration level (x = a), with F = tau - b(q, v) [N or N m].
        x_free: the unconstrained solution, shape (nv,): v + dt a_free or a_free.
    """

    M: np.ndarray
    g: np.ndarray
    x_free: np.ndarray


@dataclass(frozen=True)
class FloatingBases:
    """The free-flyer joints hung from the world, integrated on R3 x SO(3) (see :mod:`.integrator`).

    Pinocchio's free-flyer velocity is the body twist: its linear part v_l is the origin's velocity in
    the body frame, whose rotation adds -w x v_l to ABA's acceleration; advanced explicitly, that term
    turns and stretches v_l every step (a spinning body speeds up). gaussim's step instead takes v_l as
    the origin's velocity in the frame of the step's start, R v_l fixed while the frame turns: the free
    motion leaves that term out, the translation moves by dt R v_l+ and v_l+ is re-expressed in the new
    frame. A base that is one rigid body with its centre of mass at the joint (a free object) also gets
    its gyroscopic term w x I w at the step's midpoint, I (w+ - w) = dt (tau - w_m x I w_m) with
    w_m = (w + w+) / 2, which conserves its energy and |I w| exactly in free flight.

    Attributes:
        velocity: first velocity index of each base, shape (k,).
        configuration: first configuration index of each base, shape (k,).
        inertias: rotational inertia about the joint of each rigid base, zeros for the others, (k, 3, 3)
            [kg m^2].
        rigid: which bases are one rigid body with its centre of mass at the joint, shape (k,).
        of_joint: which base each joint is, -1 for the others, shape (njoints,).
    """

    velocity: np.ndarray
    configuration: np.ndarray
    inertias: np.ndarray
    rigid: np.ndarray
    of_joint: np.ndarray

    @classmethod
    def of(cls, model: pin.Model) -> FloatingBases:
        joints = [
            j
            for j in range(1, model.njoints)
            if model.parents[j] == 0 and model.joints[j].shortname() == "JointModelFreeFlyer"
        ]
        inertias = np.zeros((len(joints), 3, 3))
        rigid = np.zeros(len(joints), dtype=np.bool_)
        for k, j in enumerate(joints):
            body = model.inertias[j]
            # a lever below a nanometre: the centre of mass is at the joint
            if len(model.subtrees[j]) == 1 and float(np.linalg.norm(body.lever)) < 1e-9:
                inertias[k], rigid[k] = body.inertia, True
        of_joint = np.full(model.njoints, -1, dtype=np.int64)
        of_joint[joints] = np.arange(len(joints))
        return cls(
            np.array([model.joints[j].idx_v for j in joints], dtype=np.int64),
            np.array([model.joints[j].idx_q for j in joints], dtype=np.int64),
            inertias,
            rigid,
            of_joint,
        )

    def __len__(self) -> int:
        return len(self.velocity)

    def untouched(self, *reports: object) -> np.ndarray:
        """Which bases are rigid and take no reaction from the blocks of these step reports (a report
        or None each): no row with a nonzero multiplier reads them, shape (k,). Free flight, where
        :mod:`.integrator` turns them by the midpoint rule (a contact within its margin that the step
        does not reach leaves its body free)."""
        free = self.rigid.copy()
        for report in reports:
            for _, rows, multipliers in getattr(report, "blocks", ()):
                if rows.joints is None:
                    unloaded.call(rows.J, multipliers, self.velocity, free)
                else:  # a rigid base is its tree's one joint: a row loads it when it reads that joint
                    loaded.call(rows.joints, multipliers, self.of_joint, free)
        return free

    def frame_acceleration(self, v: np.ndarray) -> np.ndarray:
        """The body-frame acceleration -w x v_l of each base's origin at fixed world velocity, zeros
        elsewhere, shape (nv,): ABA's acceleration less the gauss problem's (its drift terms add it)."""
        c = np.empty(len(v))
        frame_accelerations.call(v, self.velocity, c)
        return c


@dataclass(frozen=True)
class MassStructure:
    """M's joint structure: M[i, j] != 0 only when coordinates i and j move on one branch of the joint
    tree. A model of many trees (a pile of free bodies) or a long one has mostly zeros in M, and its
    products and LDL^T factor (:func:`structured_solve`) cost O(its nonzeros).

    A world of free bodies (each tree one body on a free-flyer joint) has a constant M: Pinocchio's
    free-flyer velocity is the body's twist in its own frame, so its block of M is the body's spatial
    inertia there, at every configuration. Its step then needs no CRBA and no factorization, only the
    Jacobians and RNEA's b(q, v), O(nv) (``constant``). M is taken from the model's inertias when
    the structure is made: inertias changed on the model afterwards are not read (its armature is).

    Attributes:
        parents: the coordinate before each on its branch, -1 at a root, shape (nv,) (Pinocchio's
            data.parents_fromRow).
        subtree: how many coordinates from each on move with it, itself included, shape (nv,)
            (data.nvSubtree_fromRow).
        M, U, D: M mirrored on its structure, its unit upper factor and its diagonal: buffers
            overwritten by each step's dynamics (zero off the structure); when constant, M and its
            factors, made again only when the model's armature changes (an implicit damping, see
            :mod:`.actuation`).
        held: when M is constant, (the armature M holds, M's diagonal without it), else None.
    """

    parents: np.ndarray
    subtree: np.ndarray
    M: np.ndarray
    U: np.ndarray
    D: np.ndarray
    held: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def constant(self) -> bool:
        """Whether M is the same at every configuration (a world of free bodies)."""
        return self.held is not None

    def armature(self, model: pin.Model) -> tuple[np.ndarray, ...]:
        """What :func:`~gaussim.kernels.dynamics.armed` reads of a constant M: (the model's armature,
        the one M holds, M's diagonal without it)."""
        assert self.held is not None
        return (model.armature, *self.held)

    @classmethod
    def of(cls, model: pin.Model, data: pin.Data) -> MassStructure | None:
        """The structure of a world of free bodies, or of a model of STRUCTURED_NV coordinates or
        more, else None (dense is cheaper). ``data``: the model's (a constant M is computed in it)."""
        nv = model.nv
        parents = np.array(data.parents_fromRow, dtype=np.int64)
        subtree = np.array(data.nvSubtree_fromRow, dtype=np.int64)
        if nv and len(FloatingBases.of(model)) == model.njoints - 1:  # every joint a free body's
            upper = pin.crba(model, data, pin.neutral(model), _WORLD)  # the same at any q
            M = np.zeros((nv, nv))
            mirrored(upper, subtree, M)
            # the armature M holds: none yet, so the first step puts the model's in and factors M
            held = (np.full(nv, np.nan), np.diag(M) - model.armature)
            return cls(parents, subtree, M, np.zeros((nv, nv)), np.zeros(nv), held)
        if nv < STRUCTURED_NV:
            return None
        return cls(parents, subtree, np.zeros((nv, nv)), np.zeros((nv, nv)), np.zeros(nv))


class TreeFactors(NamedTuple):
    """Views of Pinocchio's factors M = U D U^T in a model's data (filled by ``pin.cholesky.decompose``)
    and the joint tree they follow: what :func:`~gaussim.kernels.dynamics.factored_terms` reads."""

    U: np.ndarray
    D: np.ndarray
    parents: np.ndarray
    subtree: np.ndarray

    @classmethod
    def of(cls, data: pin.Data) -> TreeFactors:
        """The views of ``data``'s factors (they follow every decomposition of that data)."""
        parents = np.array(data.parents_fromRow, dtype=np.int64)
        return cls(data.U, data.D, parents, np.array(data.nvSubtree_fromRow, dtype=np.int64))


class DynamicsStage:
    """Stage 1 for one Pinocchio model and data: each step's free motion and, when a constraint needs
    it, its Gauss problem.

    Two orders give the same numbers at different costs: a step that poses a QP is cheapest as
    CRBA + RNEA + Cholesky (:func:`compute_dynamics`; RNEA alone for a constant M), free flight as ABA
    alone (:meth:`free_motion`).
    Each step takes the order the previous one needed; the acceleration scheme always poses its
    problem.
    """

    def __init__(self, model: pin.Model, data: pin.Data) -> None:
        self.model, self.data = model, data
        self.bases = FloatingBases.of(model)
        self.structure = MassStructure.of(model, data)
        self.factors = TreeFactors.of(data) if self.structure is None else None
        self._base_args = (self.bases.velocity, self.bases.inertias, self.bases.rigid)
        self._posed = True  # the last step posed a Gauss problem
        self._dynamics: Dynamics | None = None
        self._pending: tuple[np.ndarray, np.ndarray] | None = None  # (q, x_free) of the ABA order
        self._nv = model.nv  # a plain int: the model's is a property
        # sum_i |v_i| + |x_free_i| with it (else None): the collision stage's coarse bound on how far the
        # step can move any point, per unit of lever (see ContactDetector.cover)
        self.reach: float | None = None

    def free_motion(
        self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, dt: float, acceleration: bool = False
    ) -> np.ndarray:
        """The unconstrained solution x_free of the velocity level or, with ``acceleration``, of the
        acceleration level, for a time step ``dt`` [s] and joint torques ``tau`` (nv,); the joint
        placements data.oMi for detection on the way.

        Raises :class:`InvalidState` when tau is not finite, :class:`SolverError` when ABA's answer is
        not at a finite tau."""
        if len(tau) != self._nv:  # the kernels read nv entries
            raise InvalidState(f"tau must have shape ({self._nv},), got {np.shape(tau)}")
        if acceleration or self._posed:
            self._posed, self.reach = False, None
            self._dynamics = compute_dynamics(
                self.model, self.data, q, v, tau, dt, acceleration, self.bases, self.structure, self.factors
            )
            return self._dynamics.x_free
        # the WORLD convention fills data.oMi, and costs less than LOCAL
        a_free = pin.aba(self.model, self.data, q, v, tau, _WORLD)
        x_free = np.empty(self._nv)  # filled by the kernel: cheaper than a kernel's new array
        # tau is checked only here, where a NaN in it shows
        reach = free_velocity.call(v, a_free, dt, x_free, *self._base_args)
        if not reach < np.inf:  # NaN: x_free is not finite
            if not np.all(np.isfinite(tau)):
                raise InvalidState.non_finite("tau", tau)
            raise SolverError("the free motion (Pinocchio's ABA) is not finite at a finite state and torque")
        self._dynamics, self._pending, self.reach = None, (q, x_free), reach
        return x_free

    def problem(self) -> Dynamics:
        """The Gauss problem of the last free motion (posed now when that skipped it)."""
        self._posed = True
        if self._dynamics is None:
            assert self._pending is not None
            self._dynamics = gauss_problem(self.model, self.data, *self._pending, self.structure)
        return self._dynamics


def compute_dynamics(
    model: pin.Model,
    data: pin.Data,
    q: np.ndarray,
    v: np.ndarray,
    tau: np.ndarray,
    dt: float,
    acceleration: bool = False,
    bases: FloatingBases | None = None,
    structure: MassStructure | None = None,
    factors: TreeFactors | None = None,
) -> Dynamics:
    """M, joint placements and Jacobians (one CRBA pass, none for a constant M), b (RNEA), and the free
    Gauss problem of the velocity level or, with ``acceleration``, of the acceleration level, for a
    time step ``dt`` [s]; at the acceleration level, the spatial accelerations at zero acceleration of
    the problem's coordinates that its constraint terms Jdot v read (see :func:`point_drifts`). Frame
    placements are left to the modules that use frames.

    ``tau`` (nv,) are the joint torques; raises :class:`InvalidState` when they are not finite
    (checked here, in the kernel that reads them). The ``bases`` (default: the model's) are posed as
    :class:`FloatingBases` says. With a ``structure``, M is its buffer and every product and solve
    runs on it; without, M is dense and factored by Pinocchio into ``factors`` (default: ``data``'s).
    """
    if len(tau) != model.nv:  # the kernel reads nv entries
        raise InvalidState(f"tau must have shape ({model.nv},), got {np.shape(tau)}")
    bases = FloatingBases.of(model) if bases is None else bases
    base_args = (bases.velocity, bases.inertias, bases.rigid)
    x_free = np.empty(len(v))
    if structure is None:  # a copy of data.M; the WORLD convention also fills data.oMi, data.J
        M = pin.crba(model, data, q, _WORLD)
        nle = pin.nonLinearEffects(model, data, q, v)
        pin.cholesky.decompose(model, data)
        tree = TreeFactors.of(data) if factors is None else factors
        g = factored_terms.call(M, *tree, v, tau, nle, dt, acceleration, *base_args, x_free)
    elif structure.constant:  # data.oMi and data.J (WORLD), b, then one kernel
        pin.computeJointJacobians(model, data, q)
        nle = pin.nonLinearEffects(model, data, q, v)
        parts = (structure.M, structure.U, structure.D, structure.parents, structure.subtree)
        M = structure.M
        g = constant_terms.call(
            *parts, structure.armature(model), v, tau, nle, dt, acceleration, *base_args, x_free
        )
    else:  # M's upper triangle, b, data.oMi and data.J (WORLD), O(nv)
        pin.crba(model, data, q, _WORLD)  # not computeAllTerms: its centroidal and energy terms go unread
        pin.nonLinearEffects(model, data, q, v)
        M, f = structure.M, np.empty(len(v))
        h = 0.0 if acceleration else dt
        if structured_terms.call(data.M, structure.subtree, v, tau, data.nle, h, M, f):
            factor = (structure.U, structure.D)
            structured_solve.call(M, structure.parents, structure.subtree, f, *factor, x_free)
            g = -f
            if len(bases):
                floating_terms.call(v, x_free, dt, acceleration, *base_args)
                g = _negated(M, x_free, structure)
        else:
            g = None
    if g is None:
        raise InvalidState.non_finite("tau", tau)
    if acceleration:  # the drifts of the bases' velocity coordinates: the frame's turn is part of them
        pin.forwardKinematics(model, data, q, v, bases.frame_acceleration(v))
    return Dynamics(M, g, x_free)


def gauss_problem(
    model: pin.Model,
    data: pin.Data,
    q: np.ndarray,
    x_free: np.ndarray,
    structure: MassStructure | None = None,
) -> Dynamics:
    """The free Gauss problem of the velocity level from its free motion x_free (ABA's, see
    :meth:`DynamicsStage.free_motion`): M and the joint Jacobians data.J (one CRBA pass, or the
    Jacobians alone for a constant M; WORLD convention) and g = -M x_free; with a ``structure``, M is
    its buffer."""
    if structure is None:
        M = pin.crba(model, data, q, _WORLD)  # a copy of data.M
    elif structure.constant:  # the Jacobians alone
        pin.computeJointJacobians(model, data, q)
        M = structure.M
        tree = (structure.U, structure.D, structure.parents, structure.subtree)
        armed.call(M, *tree, structure.armature(model))
    else:
        pin.crba(model, data, q, _WORLD)  # not computeAllTerms: its RNEA and centroidal terms go unread
        M = structure.M
        mirrored(data.M, structure.subtree, M)
    return Dynamics(M, _negated(M, x_free, structure), x_free)


def _negated(M: np.ndarray, x: np.ndarray, structure: MassStructure | None) -> np.ndarray:
    """-M x, on M's structure when there is one."""
    if structure is None:
        return negated_product.call(M, x)
    return -structured_product.call(M, structure.subtree, x)


def point_placements(
    data: pin.Data, joints: list[int], points: Sequence[np.ndarray] | np.ndarray
) -> list[pin.SE3]:
    """Placements, relative to their joints, of world-aligned frames at world ``points`` (m, 3) [m]."""
    return [pin.SE3(_IDENTITY, data.oMi[j].actInv(p)) for j, p in zip(joints, points)]


class Supports(NamedTuple):
    """Which velocity coordinates move each joint's body (a tuple: the kernels take its arrays).

    Attributes:
        masks: masks[j, k] = 1 when v[k] belongs to joint j or to one of its ancestors, shape
            (njoints, nv) (row 0, the world, is all zero).
        starts, columns: the same as CSR rows (row starts (njoints + 1,), coordinates), which the
            kernels loop over: a contact of two free bodies reads 12 of a pile's hundreds of
            coordinates.
    """

    masks: np.ndarray
    starts: np.ndarray
    columns: np.ndarray

    @classmethod
    def of(cls, model: pin.Model) -> Supports:
        masks = np.zeros((model.njoints, model.nv))
        for j in range(1, model.njoints):
            for ancestor in model.supports[j][1:]:
                joint = model.joints[ancestor]
                masks[j, joint.idx_v : joint.idx_v + joint.nv] = 1.0
        starts, columns, _ = sparse_rows(list(masks))
        return cls(masks, starts, columns)


def sparse_rows(dense: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows in CSR form: (row starts, the columns of their nonzero entries, those entries)."""
    nonzero = [np.flatnonzero(row) for row in dense]
    starts = np.cumsum([0] + [len(k) for k in nonzero])
    columns = np.concatenate([np.zeros(0, np.int64), *nonzero]).astype(np.int64)
    values = np.concatenate([np.zeros(0), *(row[k] for row, k in zip(dense, nonzero))])
    return starts, columns, values


def point_jacobians(
    data: pin.Data, supports: Supports, joints: np.ndarray, other_joints: np.ndarray, points: np.ndarray
) -> np.ndarray:
    """Jacobians of the relative world velocities of body points, shape (m, 3, nv).

    Row i maps v to the velocity of the point ``points[i]`` (world frame, (m, 3)) of the body of
    ``joints[i]`` minus that of the same point moving with ``other_joints[i]`` (0, the world, for a
    fixed obstacle). Read from the joint Jacobians in data.J (WORLD frame, filled with M):
    the point moves at v_O + w x p over the columns of the joint's ancestors (``supports``), and the
    ancestors the two bodies share cancel.
    """
    J = joint_jacobians(data)
    result = np.empty((len(joints), 3, J.shape[1]))
    point_jacobians_into.call(result, J, *supports, joints, other_joints, points)
    return result


def joint_jacobians(data: pin.Data) -> np.ndarray:
    """data.J, shape (6, nv), as a view (eigenpy returns a 6 x 1 matrix as a vector of shape (6,): a
    one-dof robot's)."""
    return data.J.reshape(6, -1)


def point_drifts(
    model: pin.Model, data: pin.Data, joints: list[int], placements: list[pin.SE3]
) -> np.ndarray:
    """Classical accelerations of body points at zero joint acceleration (Jdot v), shape (m, 3) [m/s^2].

    Needs the spatial accelerations of a forward pass with a = 0 (``compute_dynamics(drifts=True)``).
    """
    return np.array(
        [pin.getFrameClassicalAcceleration(model, data, j, M, LWA).linear for j, M in zip(joints, placements)]
    )

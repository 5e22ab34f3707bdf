"""Compile the kernels into numba's cache ahead of the first run: ``python -m gaussim.kernels.prebuild``.

The build runs it (setup.py) on the package it installs, so that the numba cache files
(``__pycache__/*.nbi``, ``*.nbc``) ship beside the kernels. numba takes a cached kernel when its source
file's content, numba's version and the machine's CPU match the ones it was compiled with; else it
compiles the kernel at its first call, as without this module.

Each signature is written in a short code, one token per argument: ``f``, ``i``, ``b`` (float64, int64,
bool scalars), ``f2`` (a float64 array of 2 dimensions, C order), ``F`` after the dimensions for
Fortran order, ``r`` for a read-only array (``f1r``), ``*n`` for a tuple of n of them (``f2F*4``).
"""

from __future__ import annotations

import importlib
import sys
import time

from numba.core import types
from numba.core.registry import CPUDispatcher

_DTYPES = {"f": types.float64, "i": types.int64, "b": types.boolean}
_CODES: dict[types.Type, str] = {dtype: code for code, dtype in _DTYPES.items()}

_SIDES = ("f2 f1 f2 f1", "f2 f1 f2r f1r", "f2r f1r f2 f1")

# The signatures the shipped scenes call the kernels with from Python (both schemes): tests/test_kernels.py
# checks that the main job needs no other. A stage's kernel is bound to the first one its first call fits
# (gaussim.kernels.bound): a matrix that is both C- and F-contiguous (1 x n) fits either order, so the
# order a call site passes in general comes first.
SIGNATURES = {
    "dynamics.factored_terms": [
        f"f2 {U} f1 i1 i1 {v} {tau} f1 f b i1 f3 b1 f1"
        for U in ("f2F", "f2")  # Pinocchio's U: column-major, C as well at nv = 1
        for v in ("f1", "f1r")
        for tau in ("f1", "f1r")
    ],
    "dynamics.free_velocity": ["f1r f1 f f1 i1 f3 b1"],
    "dynamics.floating_terms": ["f1r f1 f b i1 f3 b1", "f1 f1 f b i1 f3 b1"],
    "dynamics.negated_product": ["f2 f1"],
    "dynamics.frame_accelerations": ["f1r i1 f1", "f1 i1 f1"],
    "dynamics.point_jacobians_into": ["f3 f2F f2 i1 i1 i1r i1r f2", "f3 f2F f2 i1 i1 i1 i1 f2"],
    "dynamics.unloaded": ["f2 f1 i1 b1"],
    "dynamics.loaded": ["i2 f1 i1 b1"],
    # M's joint structure: scenes of many coordinates (STRUCTURED_NV or more) and worlds of free bodies
    "dynamics.mirrored": ["f2F i1 f2", "f2 i1 f2"],
    "dynamics.structured_terms": [
        f"f2F i1 {v} {tau} f1 f f2 f1" for v in ("f1", "f1r") for tau in ("f1", "f1r")
    ],
    "dynamics.structured_product": ["f2 i1 f1", "f2 i1 f1r"],
    "dynamics.structured_solve": ["f2 i1 i1 f1 f2 f1 f1"],
    "dynamics.structured_factor": ["f2 i1 i1 f2 f1"],
    "dynamics.armed": ["f2 f2 f1 i1 i1 f1*3"],
    "dynamics.constant_terms": [
        f"f2 f2 f1 i1 i1 f1*3 {v} {tau} f1 f b i1 f3 b1 f1" for v in ("f1", "f1r") for tau in ("f1", "f1r")
    ],
    "integrator.displacement": ["f1r f1 f i1 b1 f1"],
    "integrator.move_bases": ["f1r f1 f1 f i1 i1"],
    "actuation.damped_torque": ["f1 f1 f1r f1 f1"],
    # the joints' placements: one array whatever the scene (gaussim.kernels.pairs)
    "collision.ground_hulls": ["f3r i1 f2 f3 i2 i2 i1 i1 f2 f1 f1 f3 f f*2 f1 f1 i1"],
    "pairs.sphere_gaps": ["f3r i2 f3 f1 f1 f3 f f1"],
    "pairs.nearby": ["f1 f"],
    "pairs.point_keys": ["i1 i i1"],
    "pairs.gathered": ["i1 i1 i1 f1 f2 f3 i1 f"],
    "pairs.support_gaps": ["f3r i2 f2 i1 f1 f3 f3 f1 f f1"],
    "boxes.box_pairs": ["f3r i2 f4 f3 f3 b1 i1 f i1 f1 f2 f3 i1"],
    "primitives.primitive_pairs": ["f3r i2 f4 f3 i2 f3 i1 f i1 f1 f2 f3 i1"],
    "cylinders.ground_cylinders": ["f3r i2 f4 f3 f2 f2 i1 f i1 f1 f2 f3 i1"],
    "collision.in_pair_order": ["i1 f2 f2 f1"],
    "collision.joined": ["i1 f2 f2 f1 i1 f2 f2 f1"],
    "collision.travel": ["i1 i1 f1 i1 i1 f1 f1r f1 f f f1 f1"],
    "collision.closing": [f"f2F f2 i1 i1 i1 i1 f2 f2 f1 {v} f1 f f f1" for v in ("f1r", "f1")],
    "contact.near_limits": ["f1r f1r i1 i1 f1 f1 i f*5 i1 f1", "f1r f1 i1 i1 f1 f1 i f*5 i1 f1"],
    "contact.restricting": ["i f1 f1 f f f f"],
    "contact.unpacked": ["f1 i i"],
    "contact.pyramids": [
        f"f2F f2 i1 i1 {joints} {joints} f2 {v} {x} f2r f2 f1 {mu} {mu} f2r b1r f1r i f1 f1 b f*3 "
        "f2 f1 f1 i1 i2"
        for joints, mu in (("i1", "f1"), ("i1r", "f1r"))  # all the contacts, or those a level keeps
        for v, x in (("f1", "f1"), ("f1r", "f1"), ("f1r", "f1r"))
    ],
    "contact.contact_row_ids": ["i1 i1 i", "i1 i1r i"],
    "contact.secant_moves": ["f2 f2 f2 f2 f*2 f2 f2"],
    "contact.newton_moves": ["f2r f2r f2r f1 f i i1 f1 f1r f2 f2 f*2 f2"],
    "contact.shifted_bounds": [f"f1 i1 {mu} f2 f2 f1" for mu in ("f1", "f1r")],
    "contact.slips": [
        f"f1 f2 i1 f1 f2 {mu} f2 f1 {joints} {joints} i1 i1 f2"
        for joints, mu in (("i1", "f1"), ("i1r", "f1r"))
    ],
    # the equalities (A, b) or the inequalities (C, l) of a problem are read-only when empty
    "solver.kkt_residuals": [f"f2 f1 {sides} f1 f1 f1" for sides in _SIDES],
    "solver.violates": ["f2 f1 f1 f", "f2r f1r f1 f"],
    "solver.active_set_candidate": [
        "f2 f1 f2 f1 f2 f1 f1 f1 f f f1 f1",
        "f2 f1 f2 f1 f2r f1r f1 f1 f f f1 f1",
        "f2 f1 f2 f1 f2r f1r f1r f1 f f f1 f1",
        "f2 f1 f2r f1r f2 f1 f1 f1 f f f1 f1",
        "f2 f1 f2r f1r f2 f1 f1r f1 f f f1 f1",
    ],
    "solver.read_results": [f"f2 f1 {sides} f1 f1 f1" for sides in _SIDES],
    # the reactions reported: the least-norm multipliers (A, C and l of the _SIDES)
    "solver.least_norm": [f"f2 f1 {rows} f1 f f1" for rows in ("f2 f2 f1", "f2 f2r f1r", "f2r f2 f1")],
    # the scenes of several bodies: their islands, and each one's problem
    "solver.islands": [f"{a} {c} i2 i1 f1 i1 i" for a, c in (("f2r", "f2"), ("f2", "f2"), ("f2", "f2r"))],
    "solver.members": ["i1 i"],
    "solver.within": ["i1 i"],
    "solver.box_minimum": ["f2 f1 f1 f1 f f f1"],
    "solver.matched_values": ["i1 f1 i1 f1", "i1r f1 i1r f1"],
    "solver.cut": [f"f2 f1 {sides} i1 i1 i1" for sides in _SIDES],
    "solver.warm_islands": [f"f2 f1 {sides} i1*6 b1 f1 f1 f i1 f2 f1 f1" for sides in _SIDES],
    # the dual active-set method: a problem's factors and rows, its working set, its answer
    "dual.envelope_cholesky": ["f2 f2 i1 i1"],
    "dual.transformed_rows": ["f2 i1 i1 f2 i1 i1 f1 i1 f1 i1", "f2 i1 i1 f2r i1 i1 f1 i1 f1 i1"],
    "dual.free_products": ["f2 i1 f1 i1 i1 f1 f1 f1"],
    "dual.start_set": ["i1 i1 f1 i1 i f1 f i1 f2 f1 i1 f1 i1 f1 f1"],
    "dual.dual_iterations": [
        f"i1 i1 f1 i1 f1 {d} i f f i i i1 f2 f1 i1 f1 i1 f1 f1 f2" for d in ("f1", "f1r")
    ],
    "dual.primal_answer": ["f2 i1 f1 i i1 f1 f1 f1"],
}


def parse(code: str) -> tuple[types.Type, ...]:
    """The argument types a signature code (module docstring) stands for."""
    return tuple(_parse_one(token) for token in code.split())


def _parse_one(token: str) -> types.Type:
    if "*" in token:
        item, count = token.split("*")
        return types.UniTuple(_parse_one(item), int(count))
    dtype = _DTYPES[token[0]]
    if len(token) == 1:
        return dtype
    return types.Array(dtype, int(token[1]), "F" if "F" in token else "C", readonly="r" in token)


def code_of(signature: tuple[types.Type, ...]) -> str | None:
    """The code of a signature of argument types, None when it holds a type the codes do not write."""
    tokens = [_code_of_one(t) for t in signature]
    return " ".join(t for t in tokens if t is not None) if None not in tokens else None


def _code_of_one(t: types.Type) -> str | None:
    if isinstance(t, types.UniTuple):
        item = _code_of_one(t.dtype)
        return None if item is None else f"{item}*{t.count}"
    if isinstance(t, types.Array):
        if t.dtype not in _CODES or t.layout not in "CF" or (t.ndim < 2 and t.layout == "F"):
            return None
        return f"{_CODES[t.dtype]}{t.ndim}{'F' if t.layout == 'F' else ''}{'r' if not t.mutable else ''}"
    return _CODES.get(t)


def kernel(name: str) -> CPUDispatcher:
    """The kernel ``module.function`` of gaussim.kernels."""
    module, function = name.split(".")
    return getattr(importlib.import_module(f"gaussim.kernels.{module}"), function)


def load() -> int:
    """Compile every kernel for its SIGNATURES, or load it from numba's cache (which a process does at
    a kernel's first call: tens of ms, which a timed step should not pay); returns their number."""
    for name, codes in SIGNATURES.items():
        dispatcher = kernel(name)
        for code in codes:
            dispatcher.compile(parse(code))
    return sum(map(len, SIGNATURES.values()))


def main() -> int:
    """Compile every kernel for its SIGNATURES (a cached one is loaded, not compiled again)."""
    start = time.perf_counter()
    count = load()
    print(f"gaussim: {count} kernel signatures compiled in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())

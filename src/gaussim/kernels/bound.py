"""Kernels the step calls past numba's dispatcher.

numba's dispatcher types every argument of every call to pick a compiled overload (30 to 60 ns an
array): on Solo-12 standing, the step's nine kernel calls and their 112 arguments spent 3 to 5 us of
its 45 us there. A :class:`Bound` kernel picks its overload once, at its first call: the first of the
kernel's declared signatures (:data:`.prebuild.SIGNATURES`) that the arguments fit, whose overload's
entry point it calls from then on (a first call that fits none leaves it with the dispatcher). Its
call site passes arrays gaussim makes, whose dtype, dimensions and memory order do not change
between calls; read-only flags may (they change no machine code). The entry point does not check
them: the arrays of a user's making that reach a kernel (a torque, a module's :class:`Rows`, a
:class:`GaussProblem`, a material's coefficients) are made C-ordered float64 first
(:func:`~gaussim.constraints.base.real_floats`; int64: :func:`c_int`). With
``GAUSSIM_CHECK_KERNELS=1`` (the test suite's setting) each later call's arguments are checked against
the bound signature, a misfit raising TypeError, and so is a first call that fits no declared
signature.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np
from numba._dispatcher import compute_fingerprint
from numba.core import types
from numba.core.registry import CPUDispatcher
from numba.np.numpy_support import as_dtype

from .prebuild import SIGNATURES, kernel, parse

CHECK = os.environ.get("GAUSSIM_CHECK_KERNELS", "") not in ("", "0")
_FLOAT, _INT = np.dtype(np.float64), np.dtype(np.int64)


def is_c_float(a: object) -> bool:
    """Whether ``a`` is a C-contiguous native float64 array, what the bound kernels read."""
    return type(a) is np.ndarray and a.dtype is _FLOAT and a.flags.c_contiguous


def c_int(a: object) -> np.ndarray:
    """``a`` itself when a C-contiguous int64 array, else such a copy (values cast as numpy casts)."""
    if type(a) is np.ndarray and a.dtype is _INT and a.flags.c_contiguous:
        return a
    return np.ascontiguousarray(np.asarray(a).astype(_INT, copy=False))


class Bound:
    """Kernel ``name`` (``module.function`` of gaussim.kernels) for one call site: call ``.call``."""

    __slots__ = ("name", "dispatcher", "call", "_signatures")

    def __init__(self, name: str) -> None:
        self.name = name
        self.dispatcher = kernel(name)
        self._signatures = [parse(code) for code in SIGNATURES[name]]
        # with NUMBA_DISABLE_JIT the kernel is its Python function: no overload to bind
        compiled = isinstance(self.dispatcher, CPUDispatcher)
        self.call: Callable[..., Any] = self._first if compiled else self.dispatcher

    def __call__(self, *args: Any) -> Any:
        """The kernel's answer (``.call`` itself costs less where each step pays it)."""
        return self.call(*args)

    def _first(self, *args: Any) -> Any:
        """Bind the overload of the first declared signature that ``args`` fit (read-only flags aside,
        and a matrix both C- and F-contiguous fitting either order: the declared order decides), and
        call it; with no signature fitting, the dispatcher stays (it types each call)."""
        signature = next((s for s in self._signatures if _fits(args, s)), None)
        if signature is None:
            if CHECK:  # a type the build did not declare: a test should see it
                raise TypeError(f"kernel {self.name} called with ({_shown(args)}), no declared signature")
            self.call = self.dispatcher
        else:
            entry = _entry_point(self.dispatcher, signature)
            self.call = _checked(self.name, signature, entry) if CHECK else entry
        return self.call(*args)


def _entry_point(dispatcher: Any, signature: tuple[types.Type, ...]) -> Callable[..., Any]:
    if signature not in dispatcher.overloads:
        dispatcher.compile(signature)  # loaded from numba's cache when the build compiled it
    return dispatcher.overloads[signature].entry_point


def _checked(name: str, signature: tuple[types.Type, ...], entry: Callable[..., Any]) -> Callable[..., Any]:
    specs = [_spec(kind) for kind in signature]
    seen: set[tuple[object, ...]] = set()  # numba's fingerprints of the argument types checked already

    def call(*args: Any) -> Any:
        # numba's fingerprint leaves out the byte order: the dtypes too
        key = (*map(compute_fingerprint, args), *(a.dtype for a in args if type(a) is np.ndarray))
        if key not in seen:
            if len(args) != len(specs) or not all(map(_fits_spec, args, specs)):
                bound = ", ".join(map(str, signature))
                raise TypeError(f"kernel {name} bound to ({bound}) called with ({_shown(args)})")
            if not any(_ambiguous(a) for a in args):  # its fingerprint tells the order
                seen.add(key)
        return entry(*args)

    return call


def _ambiguous(value: Any) -> bool:
    """An array whose fingerprint says C order where it is also F-contiguous (or the reverse)."""
    return (
        isinstance(value, np.ndarray)
        and value.ndim > 1
        and value.flags.c_contiguous
        and value.flags.f_contiguous
    )


def _shown(args: tuple[Any, ...]) -> str:
    return ", ".join(_array(a) if isinstance(a, np.ndarray) else type(a).__name__ for a in args)


def _array(a: np.ndarray) -> str:
    order = "C" if a.flags.c_contiguous else "F" if a.flags.f_contiguous else "A"
    return f"{a.dtype}[{a.ndim}d, {order}]"


def _fits(args: tuple[Any, ...], signature: tuple[types.Type, ...]) -> bool:
    return len(args) == len(signature) and all(map(_fits_spec, args, map(_spec, signature)))


Spec = tuple[Any, ...]
_SCALARS: dict[types.Type, tuple[type, ...]] = {
    types.boolean: (bool, np.bool_),
    types.int64: (int, np.integer),
    types.float64: (float, np.floating),
}


def _spec(kind: types.Type) -> Spec:
    """What a value of numba type ``kind`` must be: ("array", dtype, ndim, contiguity flag), ("tuple",
    count, item's spec) or ("scalar", Python types)."""
    if isinstance(kind, types.Array):
        return (
            "array",
            as_dtype(kind.dtype),
            kind.ndim,
            "C_CONTIGUOUS" if kind.layout == "C" else "F_CONTIGUOUS",
        )
    if isinstance(kind, types.UniTuple):
        return ("tuple", kind.count, _spec(kind.dtype))
    return ("scalar", _SCALARS[kind])


def _fits_spec(value: Any, spec: Spec) -> bool:
    if spec[0] == "array":
        return (
            type(value) is np.ndarray
            and value.dtype == spec[1]
            and value.ndim == spec[2]
            and bool(value.flags[spec[3]])
        )
    if spec[0] == "tuple":
        return type(value) is tuple and len(value) == spec[1] and all(_fits_spec(v, spec[2]) for v in value)
    # a bool is an int to Python, not to numba
    return isinstance(value, spec[1]) and (bool in spec[1] or not isinstance(value, (bool, np.bool_)))

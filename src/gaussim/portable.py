"""proxsuite loaded with its portable build: its AVX2 and AVX-512 builds answer a QP differently from
one QP object to the next in the last bits, so runs would not repeat bit for bit.

proxsuite picks its build at import by asking its ``instructionset`` module; importing gaussim puts
in its place one that answers "neither", until proxsuite is loaded (by gaussim's solver, or by the
user's code after ``import gaussim``). Loaded before gaussim, or when proxsuite asks that module
something else, the build proxsuite chose is used: two builds in one process abort it.
"""

from __future__ import annotations

import sys
import types

_NAME = "proxsuite.instructionset"


def _reserve() -> None:
    """Answer "neither AVX2 nor AVX-512" to proxsuite's first import, if it has not happened yet."""
    if "proxsuite" not in sys.modules and _NAME not in sys.modules:
        plain = types.ModuleType(_NAME)
        plain.has_AVX512F = plain.has_AVX2 = lambda: False  # type: ignore[attr-defined]
        sys.modules[_NAME] = plain


def portable_proxsuite() -> types.ModuleType:
    """proxsuite, imported with its portable build when this process had not loaded it before gaussim."""
    if "proxsuite" in sys.modules:
        return sys.modules["proxsuite"]
    _reserve()
    try:
        import proxsuite
    except AttributeError:  # it asked before loading any build
        proxsuite = None
    finally:
        sys.modules.pop(_NAME, None)
    if proxsuite is None:
        import proxsuite
    return proxsuite


_reserve()

"""proxsuite loaded with its portable build: its AVX2 and AVX-512 builds answer a QP differently from
one QP object to the next in the last bits, so runs would not repeat bit for bit.

proxsuite picks its build at import by asking its ``instructionset`` module; this answers "neither"
for that one import. Loaded already, or when proxsuite asks that module something else, the build
proxsuite chose is used: two builds in one process abort it.
"""

from __future__ import annotations

import sys
import types


def _portable_proxsuite() -> types.ModuleType:
    """proxsuite, imported with its portable build when this process has not loaded it yet."""
    if "proxsuite" in sys.modules:
        return sys.modules["proxsuite"]
    plain = types.ModuleType("proxsuite.instructionset")
    plain.has_AVX512F = plain.has_AVX2 = lambda: False  # type: ignore[attr-defined]
    sys.modules["proxsuite.instructionset"] = plain
    try:
        import proxsuite
    except AttributeError:  # it asked before loading any build
        proxsuite = None
    finally:
        del sys.modules["proxsuite.instructionset"]
    if proxsuite is None:
        import proxsuite
    return proxsuite


proxqp = _portable_proxsuite().proxqp

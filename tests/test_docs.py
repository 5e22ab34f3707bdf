"""Every code block of the README and of docs/*.md runs as written.

A page's ```python blocks run in order in one namespace (a tutorial builds on its earlier blocks), in
a fresh folder holding the repository's ``robots/`` and ``examples/``. A ```bash block runs line by
line in that folder, with ``gaussim`` and ``.venv/bin/...`` standing for this environment's; a line
that first makes the venv and installs the package (``python3 -m venv .venv && .venv/bin/pip install
... && rest``) runs ``rest``, since the package is installed. A ```toml block is a scene file and is
loaded. Blocks in ``text`` are output or layouts and are not run. A block opts out only with an HTML
comment just above it, ``<!-- not run: reason -->``, for what installs packages, serves until Ctrl-C
or runs for minutes.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

import gaussim

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```(\S*)\s*$")
OPT_OUT = re.compile(r"^<!-- not run: (\S.*) -->$")
RUN = ("python", "bash", "toml")
NOT_CODE = ("text",)
# the step that makes the venv and installs the package, which the test environment has done
INSTALL = re.compile(r"^python3 -m venv \.venv && \.venv/bin/pip install [^&]*&& ")
# what a bash line of the docs may run: this package's command and interpreter
COMMANDS = ("gaussim", ".venv/bin/gaussim", ".venv/bin/python", "python")


@dataclass
class Block:
    page: Path
    line: int  # of the opening fence, 1-based
    language: str
    text: str
    opt_out: str | None  # the reason given, or None


def blocks(page: Path) -> list[Block]:
    """The fenced code blocks of a page; an unclosed fence is an error."""
    lines = page.read_text().splitlines()
    found, i = [], 0
    while i < len(lines):
        match = FENCE.match(lines[i])
        if match is None:
            i += 1
            continue
        start, language = i, match[1]
        end = next((j for j in range(i + 1, len(lines)) if lines[j].startswith("```")), None)
        assert end is not None, f"{page.name}:{start + 1}: unclosed code block"
        before = next((lines[j] for j in range(start - 1, -1, -1) if lines[j].strip()), "")
        reason = OPT_OUT.match(before.strip())
        found.append(
            Block(page, start + 1, language, "\n".join(lines[start + 1 : end]) + "\n", reason and reason[1])
        )
        i = end + 1
    return found


def _where(block: Block) -> str:
    return f"{block.page.relative_to(ROOT)}:{block.line}"


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """A fresh working folder with the repository's robots and examples, and a ``.venv/bin`` (and a
    ``gaussim`` on the PATH) that run this environment's interpreter on this checkout's sources."""
    for name in ("robots", "examples"):
        (tmp_path / name).symlink_to(ROOT / name)
    bin_dir = tmp_path / ".venv" / "bin"
    bin_dir.mkdir(parents=True)
    (bin_dir / "python").symlink_to(sys.executable)
    gaussim_cli = bin_dir / "gaussim"
    gaussim_cli.write_text(f'#!/bin/sh\nexec {shlex.quote(sys.executable)} -m gaussim "$@"\n')
    gaussim_cli.chmod(0o755)
    return tmp_path


def _environment(folder: Path) -> dict[str, str]:
    env = dict(os.environ)  # NUMBA_CACHE_DIR from conftest: the kernels compiled for this run
    env["PATH"] = f"{folder / '.venv' / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT / "src"), env.get("PYTHONPATH")]))
    env["MPLBACKEND"] = "Agg"
    return env


def _run_bash(block: Block, folder: Path) -> None:
    for number, line in enumerate(block.text.replace("\\\n", " ").splitlines()):
        line = INSTALL.sub("", line.strip())
        if not line or line.startswith("#"):
            continue
        first = shlex.split(line, comments=True)[0]
        assert first in COMMANDS, (
            f"{_where(block)}: '{first}' is no command of this package; mark the block "
            "<!-- not run: reason --> if it installs things, serves or runs for minutes"
        )
        env = _environment(folder)
        result = subprocess.run(line, shell=True, cwd=folder, env=env, capture_output=True, text=True)
        assert result.returncode == 0, f"{_where(block)} line {number + 1}: {line}\n{result.stderr[-3000:]}"


def _run_python(block: Block, namespace: dict[str, object]) -> None:
    exec(compile(block.text, _where(block), "exec"), namespace)  # noqa: S102 - the docs' own code, verbatim


def _load_toml(block: Block, folder: Path) -> None:
    gaussim.scenefile.load_scene_text(block.text, folder / "scene.toml")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_page_runs(page: Path, folder: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every block of the page runs; a block in another language, or opted out without a reason, is
    an error (so that none is skipped unseen)."""
    found = blocks(page)
    for block in found:
        assert block.language in RUN + NOT_CODE, (
            f"{_where(block)}: a code block in '{block.language or 'no language'}'; "
            f"label it one of {RUN + NOT_CODE}"
        )
    monkeypatch.chdir(folder)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace: dict[str, object] = {"__name__": "__docs__"}  # one per page: its blocks build on each other
    run = {"python": lambda b: _run_python(b, namespace), "bash": lambda b: _run_bash(b, folder)}
    run["toml"] = lambda b: _load_toml(b, folder)
    for block in found:  # in the page's order: a command's output is read by the code after it
        if block.opt_out is None and block.language in run:
            run[block.language](block)


def test_blocks_are_found(tmp_path: Path) -> None:
    """The parser finds each block, its language and its opt-out (a page with one of each)."""
    page = tmp_path / "page.md"
    page.write_text(
        "text\n\n```python\nx = 1\n```\n\n<!-- not run: serves until Ctrl-C -->\n\n```bash\n"
        "gaussim replay a.runlog\n```\n    indented = 'not a fenced block'\n\n"
        "<!-- not run: -->\n```toml\n```\n"
    )
    found = blocks(page)
    assert [(b.language, b.text, b.opt_out) for b in found] == [
        ("python", "x = 1\n", None),
        ("bash", "gaussim replay a.runlog\n", "serves until Ctrl-C"),
        ("toml", "\n", None),  # an opt-out must give its reason
    ]


def test_readme_keeps_the_ci_test_command() -> None:
    """.ci/run runs the README's test command verbatim: the two must stay the same line."""
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    command = ci[ci.index("# The README's test command, verbatim:") + 1]
    readme = [b.text.strip() for b in blocks(ROOT / "README.md") if b.language == "bash"]
    assert command in readme


def test_ci_fails_when_the_test_command_fails_before_its_tests() -> None:
    """Under set -e a failure before the last && of a list passes (an install out of disk space ran no
    test and CI passed): the check after the README's command stops the run then, not otherwise."""
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    at = ci.index("# The README's test command, verbatim:") + 1
    check = ci[at + 1 : ci.index("# House style: lint and types (pyproject.toml configures both).")]
    for command, status in (("true && false && true", 1), ("true && true && true", 0)):
        script = "\n".join(["set -euo pipefail", command, *check, "exit 0"])
        assert subprocess.run(["bash", "-c", script], capture_output=True).returncode == status, command


def test_roles_hook() -> None:
    """The site's hook shows the docstrings' Sphinx roles as code (``~`` shortening the path)."""
    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "hooks.py")
    assert spec is not None and spec.loader is not None
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    html = "a :class:<code>~gaussim.world.Material</code> and :func:<code>gaussim.run</code>, <code>x</code>"
    shown = "a <code>Material</code> and <code>gaussim.run</code>, <code>x</code>"
    assert hooks.on_page_content(html) == shown

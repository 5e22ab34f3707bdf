"""Property-based checks (hypothesis) over options, states and scene files: every invalid value gets an
error naming the field, every valid one is accepted, and no NaN reaches a state."""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import gaussim
from gaussim.options import MAXIMA, Options
from gaussim.world import MAX_FRICTION

from .conftest import at_height

ANY_NUMBER = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**6), max_value=10**6),
    st.booleans(),
    st.none(),
    st.text(max_size=3),
)
SCALAR_FIELDS = [
    f.name
    for f in dataclasses.fields(Options)
    if f.name not in ("scheme", "friction_mode", "on_failure", "solver")
]


def _valid(field: str, value: object) -> bool:
    """The rule each field states in its error message (the specification under test)."""
    real = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    integer = isinstance(value, int) and not isinstance(value, bool)
    minimum = {"friction_facets": 3, "friction_iterations": 1, "max_iter": 1}
    if field in minimum:
        return integer and minimum[field] <= value <= MAXIMA[field]  # type: ignore[operator]
    if field in ("restitution_threshold", "limit_margin", "start_penetration"):
        return real and value >= 0  # type: ignore[operator]
    if field == "stabilisation":
        return real and 0 < value <= 1  # type: ignore[operator]
    if field == "timings":
        return isinstance(value, bool)
    return real and value > 0  # type: ignore[operator]


@settings(max_examples=300, deadline=None)
@given(field=st.sampled_from(SCALAR_FIELDS), value=ANY_NUMBER)
def test_every_option_value_is_accepted_or_named(field, value):
    if _valid(field, value):
        assert getattr(Options(**{field: value}), field) == value
    else:
        with pytest.raises(gaussim.InvalidOptions) as info:
            Options(**{field: value})
        assert info.value.field == field


@pytest.fixture(scope="module")
def ball_sim(ball):
    return gaussim.Simulator(gaussim.Scene(ball, ground=gaussim.Ground()))


@settings(max_examples=100, deadline=None)
@given(
    index=st.integers(min_value=0, max_value=12),
    bad=st.sampled_from([np.nan, np.inf, -np.inf]),
    height=st.floats(min_value=0.0, max_value=2.0),
)
def test_a_non_finite_entry_is_named_and_never_stepped(ball_sim, ball, index, bad, height):
    """q (7), v (6): a non-finite entry anywhere is rejected with its place."""
    q, v = at_height(ball, 0.05 + height), np.zeros(6)
    name, array, where = ("q", q, index) if index < 7 else ("v", v, index - 7)
    array[where] = bad
    with pytest.raises(gaussim.InvalidState, match=rf"{name} has non-finite entries at \[{where}\]"):
        ball_sim.reset(q, v)


@settings(max_examples=60, deadline=None)
@given(
    position=st.lists(st.floats(min_value=-1, max_value=1), min_size=3, max_size=3),
    rotation=st.lists(st.floats(min_value=-1, max_value=1), min_size=4, max_size=4).filter(
        lambda r: np.linalg.norm(r) > 1e-3
    ),
    velocity=st.lists(st.floats(min_value=-20, max_value=20), min_size=6, max_size=6),
)
def test_any_valid_state_steps_to_a_finite_state(ball_sim, position, rotation, velocity):
    """A ball anywhere near the ground, any orientation and velocity up to 20 m/s (or rad/s): the step
    returns a finite state, or a clear error, never NaN; a start more than Options.start_penetration
    inside the ground is refused with the pair and the depth."""
    q = np.concatenate([position, np.array(rotation) / np.linalg.norm(rotation)])
    q[2] += 0.1
    depth = 0.1 - q[2]  # the ball's radius less its height
    if depth > ball_sim.options.start_penetration:
        with pytest.raises(gaussim.InvalidState, match=rf"'ball_0' {1e3 * depth:.4g} mm inside 'ground'"):
            ball_sim.reset(q, np.array(velocity))
        return
    state = ball_sim.reset(q, np.array(velocity))
    for _ in range(5):
        state = ball_sim.step(state)
    assert np.isfinite(state.q).all() and np.isfinite(state.v).all()


SCENE = """[robot]
name = "ball"
floating_base = true

[initial]
q = [0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0]

[ground]
friction = {friction}
restitution = {restitution}

[options]
dt = {dt}
"""
TOML_NUMBER = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False, width=32),
    st.integers(min_value=-10, max_value=10),
    st.just("nan"),
    st.just("inf"),
    st.just('"text"'),
)


@settings(max_examples=150, deadline=None)
@given(friction=TOML_NUMBER, restitution=TOML_NUMBER, dt=TOML_NUMBER)
def test_scene_file_values_are_accepted_or_named(tmp_path_factory, friction, restitution, dt):
    """A scene file's numbers: valid ones load; an invalid one is reported with the file and its key."""
    path = tmp_path_factory.mktemp("scene") / "scene.toml"
    path.write_text(SCENE.format(friction=friction, restitution=restitution, dt=dt))

    def number(text: object) -> float | None:
        try:
            value = float(text)  # type: ignore[arg-type]
        except ValueError:
            return None
        return value if math.isfinite(value) else None

    f, e, step = number(friction), number(restitution), number(dt)
    valid = {
        "ground.friction": f is not None and 0 <= f <= MAX_FRICTION,
        "ground.restitution": e is not None and 0 <= e <= 1,
        "options.dt": step is not None and step > 0,
    }
    if all(valid.values()):
        spec = gaussim.load_scene(path)
        assert spec.options.dt == pytest.approx(step)
    else:
        with pytest.raises(gaussim.InvalidOptions) as info:
            gaussim.load_scene(path)
        assert str(path) in str(info.value)
        assert any(key in str(info.value) for key, ok in valid.items() if not ok), str(info.value)


# -- fuzzing the command line: a mutated scene file or run log exits 2 naming the file, never a traceback --

FUZZ_SCENE = """[robot]
name = "ball"
floating_base = true
[initial]
q = [0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0]
v = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
[ground]
friction = 0.8
restitution = 0.2
normal = [0.0, 0.0, 1.0]
[[obstacles]]
type = "box"
name = "table"
size = [0.5, 0.5, 0.1]
position = [2.0, 0.0, 0.05]
rpy = [0.0, 0.0, 0.0]
[contacts]
pairs = [["ball_0", "ground"], ["ball_0", "table"]]
[[bilaterals]]
type = "anchor"
frame = "ball"
position = [0.0, 0.0, 0.5]
[control]
type = "zero"
[options]
dt = 0.001
max_iter = 100
friction_facets = 4
[simulation]
duration = 0.01
""".splitlines()
TOML_VALUE = st.one_of(
    st.integers(min_value=-(10**400), max_value=10**400).map(str),
    st.floats().map(lambda x: "nan" if math.isnan(x) else str(x).replace("inf", "inf")),
    st.booleans().map(lambda b: str(b).lower()),
    st.text(max_size=8).map(lambda s: '"' + s.encode("unicode_escape").decode().replace('"', '\\\\"') + '"'),
    st.lists(st.sampled_from(["1", "0.5", '"x"', "true", "[]", "-1e300"]), max_size=8).map(
        lambda xs: "[" + ", ".join(xs) + "]"
    ),
    st.just("{ a = 1 }"),
    st.sampled_from(["1" + "0" * 400, "-1e300", "1e-320", "0", "-1"]),  # beyond a float, edges of ranges
)
KEYS = [i for i, line in enumerate(FUZZ_SCENE) if " = " in line]
MUTATION = st.one_of(  # mostly values of a wrong type or range: each reaches a different check
    *[st.tuples(st.just("value"), st.sampled_from(KEYS), TOML_VALUE)] * 6,
    st.tuples(st.just("drop"), st.integers(0, len(FUZZ_SCENE) - 1), st.none()),
    st.tuples(st.just("bytes"), st.integers(0, 600), st.binary(min_size=1, max_size=16)),
)
# a case's bound [s]: loading, checking and building a Simulator take well under it
CASE_SECONDS = 10.0


def _main(capsys, *argv):
    from gaussim.cli import main

    start = time.perf_counter()
    code = main([str(a) for a in argv])
    assert time.perf_counter() - start < CASE_SECONDS
    return code, capsys.readouterr().err


@settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))
@given(mutations=st.lists(MUTATION, min_size=1, max_size=2))
def test_a_mutated_scene_file_loads_or_exits_2_naming_it(tmp_path_factory, capsys, mutations):
    """Wrong types, missing keys, random bytes: `gaussim inspect` succeeds or exits 2 with a one-line
    message naming the file; an exception escaping main fails the test (a traceback)."""
    lines = list(FUZZ_SCENE)
    raw = None
    for kind, where, what in mutations:
        if kind == "value":
            lines[where] = lines[where].split(" = ")[0] + " = " + what
        elif kind == "drop":
            lines[where] = ""
        elif kind == "bytes":
            text = "\n".join(lines).encode()
            raw = text[:where] + what + text[where:]
    path = tmp_path_factory.mktemp("fuzz") / "scene.toml"
    path.write_bytes(raw if raw is not None else "\n".join(lines).encode())
    code, err = _main(capsys, "inspect", path)
    assert code in (0, 2), err
    if code == 2:
        assert err.startswith(f"gaussim: {path}: ") and err.count("\n") == 1, err


@pytest.fixture(scope="module")
def fuzz_log(tmp_path_factory):
    """A run log of 5 steps, its bytes and its arrays."""
    folder = tmp_path_factory.mktemp("fuzzlog")
    (folder / "scene.toml").write_text(SCENE.format(friction=0.8, restitution=0.0, dt=1e-3))
    spec = gaussim.load_scene(folder / "scene.toml")
    spec.duration = 0.005
    path = gaussim.run(spec, folder / "run").save(folder / "log.npz")
    with np.load(path) as f:
        return path.read_bytes(), {k: f[k] for k in f.files}


ARRAY = st.one_of(
    st.just(None),  # removed
    st.integers(-5, 5).map(np.array),
    st.text(max_size=5).map(np.array),
    st.lists(st.floats(allow_nan=True), max_size=6).map(np.array),
    st.tuples(st.integers(0, 4), st.integers(0, 4)).map(np.zeros),
    st.just(np.array('{"dt": "x"}')),
    st.just(np.array("[")),
)


@settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))
@given(
    damage=st.one_of(
        st.tuples(st.just("truncate"), st.floats(0.0, 1.0), st.none()),
        st.tuples(st.just("flip"), st.floats(0.0, 1.0), st.binary(min_size=1, max_size=8)),
        st.tuples(st.just("array"), st.integers(0, 40), ARRAY),
    )
)
def test_a_damaged_log_exits_2_naming_it(tmp_path_factory, capsys, fuzz_log, damage):
    """Truncated, flipped or tampered .npz logs: `gaussim forces` writes its CSV or exits 2 naming the
    file, never with a traceback."""
    raw, arrays = fuzz_log
    kind, where, what = damage
    path = tmp_path_factory.mktemp("damaged") / "log.npz"
    if kind == "truncate":
        path.write_bytes(raw[: int(where * len(raw))])
    elif kind == "flip":
        k = int(where * (len(raw) - len(what)))
        path.write_bytes(raw[:k] + bytes(a ^ b for a, b in zip(raw[k:], what)) + raw[k + len(what) :])
    else:
        key = sorted(arrays)[where % len(arrays)]
        changed = {k: v for k, v in {**arrays, key: what}.items() if v is not None}
        np.savez(path, **changed)
    code, err = _main(capsys, "forces", path, "--csv", path.with_suffix(".csv"))
    assert code in (0, 2), err
    if code == 2:
        assert err.startswith(f"gaussim: {path}: ") and err.count("\n") == 1, err

"""Bad input: clear exceptions naming the field and value, never a panic, state untouched."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ukemi


def builder():
    b = ukemi.ModelBuilder()
    b.add_body("a", mass=1.0, inertia=(0.1, 0.1, 0.1), pos=(0, 0, -1))
    b.add_joint("h", "revolute", "world", "a", axis=(0, 1, 0), child_anchor=(0, 0, 1))
    return b


@pytest.mark.parametrize(
    "mutate, cls, needles",
    [
        (lambda b: b.add_body("b", mass=-1.0, inertia=(1, 1, 1)), ukemi.ModelError,
         ["body[b].mass", "-1.0"]),
        (lambda b: b.add_body("b", mass=1.0, inertia=[[1, 0.5, 0], [0, 1, 0], [0, 0, 1]]),
         ukemi.ModelError, ["body[b].inertia", "symmetric"]),
        (lambda b: b.add_body("b", mass=1.0, inertia=(1, -1, 1)), ukemi.ModelError,
         ["body[b].inertia", "positive definite"]),
        (lambda b: b.add_body("b", mass=1.0, inertia=(1, 1, 1), quat=(1, 1, 0, 0)),
         ukemi.ModelError, ["body[b].quat", "unit"]),
        (lambda b: b.add_joint("j", "revolute", "nowhere", "a"), ukemi.ModelError,
         ["joint[j].parent", "nowhere"]),
        (lambda b: b.add_joint("j", "revolute", "world", "a", axis=(0, 0, 0), loop=True),
         ukemi.ModelError, ["joint[j].axis", "non-zero"]),
        (lambda b: b.add_joint("h", "revolute", "world", "a", loop=True, child_anchor=(0, 0, 1)),
         ukemi.ModelError, ["joint[h].name", "duplicate"]),
        (lambda b: b.add_body("a", mass=1.0, inertia=(1, 1, 1)), ukemi.ModelError,
         ["body[a].name", "duplicate"]),
        (lambda b: b.add_joint("j", "hinge-ish", "world", "a"), ukemi.ModelError,
         ["joint[j].kind", "hinge-ish"]),
        (lambda b: b.add_joint("j", "spherical", "world", "a", child_anchor=(0, 0, 1)),
         ukemi.ModelError, ["joint[j].child", "loop"]),
        (lambda b: b.add_actuator("m", joint="nope"), ukemi.ModelError,
         ["actuator[m].joint", "nope"]),
    ],
)
def test_model_errors_name_the_field(mutate, cls, needles):
    b = builder()
    with pytest.raises(cls) as err:  # raised when added or, at the latest, when compiled
        mutate(b)
        b.compile()
    assert isinstance(err.value, ValueError) and isinstance(err.value, ukemi.UkemiError)
    for n in needles:
        assert n in str(err.value), (n, str(err.value))


def test_cycle_not_declared_as_loop():
    b = ukemi.ModelBuilder()
    b.add_body("a", 1.0, (0.1, 0.1, 0.1))
    b.add_body("b", 1.0, (0.1, 0.1, 0.1))
    b.add_joint("ab", "spherical", "a", "b")
    b.add_joint("ba", "spherical", "b", "a")
    with pytest.raises(ukemi.ModelError, match="cycle"):
        b.compile()


def test_builder_argument_errors():
    b = ukemi.ModelBuilder()
    with pytest.raises(ukemi.ShapeError, match="pos"):
        b.add_body("x", 1.0, (1, 1, 1), pos=(0, 0))
    with pytest.raises(ukemi.ShapeError, match="inertia"):
        b.add_body("x", 1.0, (1, 1))
    with pytest.raises(TypeError, match="mass"):
        b.add_body("x", "heavy", (1, 1, 1))
    with pytest.raises(ukemi.InputError, match="pos"):
        b.add_body("x", 1.0, (1, 1, 1), pos=(0, np.nan, 0))
    with pytest.raises(ukemi.ModelError, match="timestep"):
        ukemi.ModelBuilder(timestep=-0.1).compile()


def test_step_argument_errors(pend):
    s = pend.make_state(qpos=[0.3])
    before = (s.qpos.copy(), s.qvel.copy(), s.time)
    with pytest.raises(ukemi.ShapeError, match="ctrl"):
        ukemi.step(pend, s, ctrl=[1.0, 2.0])
    with pytest.raises(ukemi.InputError, match="ctrl"):
        ukemi.step(pend, s, ctrl=[np.inf])
    with pytest.raises(TypeError, match="ctrl"):
        ukemi.step(pend, s, ctrl=["a"])
    with pytest.raises(ukemi.ShapeError, match="xfrc_applied"):
        ukemi.step(pend, s, xfrc_applied=np.zeros((3, 6)))
    with pytest.raises(ValueError, match="on_failure"):
        ukemi.step(pend, s, on_failure="ignore")
    with pytest.raises(TypeError, match="model"):
        ukemi.step("pendulum", s)
    with pytest.raises(ukemi.ShapeError, match="qpos"):
        pend.make_state(qpos=[0.1, 0.2])
    with pytest.raises(ukemi.InputError, match="qvel"):
        pend.make_state(qvel=[np.nan])
    with pytest.raises(ukemi.ShapeError, match="ctrls"):
        ukemi.rollout(pend, s, ctrls=np.zeros((5, 2)))
    np.testing.assert_array_equal(s.qpos, before[0])
    np.testing.assert_array_equal(s.qvel, before[1])
    assert s.time == before[2]


@pytest.mark.parametrize("size", [1, 7, 64, 65, 500])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_entries_are_named_whatever_the_size(size, bad):
    from ukemi._convert import as_float_array

    for where in (0, size - 1):
        v = np.ones(size)
        v[where] = bad
        with pytest.raises(ukemi.InputError, match=rf"`v\[{where}\]`"):
            as_float_array("v", v)
    # huge finite entries whose sum overflows are finite all the same
    huge = np.full(size, 1e308)
    np.testing.assert_array_equal(as_float_array("v", huge), huge)


def test_state_of_another_model_is_rejected(pend, free_body):
    with pytest.raises(ukemi.ModelMismatchError):
        ukemi.step(pend, free_body.make_state())


from conftest import pendulum  # noqa: E402

_PEND = pendulum()
finite = st.floats(allow_nan=True, allow_infinity=True, width=64)


@settings(max_examples=150, deadline=None)
@given(
    ctrl=st.lists(finite, min_size=0, max_size=3),
    qpos=st.lists(finite, min_size=0, max_size=3),
    mass=finite,
    inertia=st.lists(finite, min_size=2, max_size=4),
)
def test_fuzzed_inputs_raise_only_ukemi_or_builtin_errors(ctrl, qpos, mass, inertia):
    pend = _PEND
    s = pend.make_state()
    for call in (
        lambda: ukemi.step(pend, s, ctrl=ctrl, on_failure="return"),
        lambda: pend.make_state(qpos=qpos),
        lambda: _build(mass, inertia),
    ):
        try:
            call()
        except (ukemi.UkemiError, ValueError, TypeError) as exc:
            assert not isinstance(exc, ukemi.InternalError), exc
    assert s.time == 0.0 and s.qpos[0] == 0.0


def _build(mass, inertia):
    b = ukemi.ModelBuilder()
    b.add_body("a", mass=mass, inertia=inertia)
    b.add_joint("f", "floating", "world", "a")
    return b.compile()

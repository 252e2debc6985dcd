"""The eye pass's typed path state (core/transport/path_state.py) travels with the rays: gathered
by Rays.take, joined by Rays.concat, inherited (a shallow copy) by Rays.moved."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from opal_diffraction.core.transport.path_state import Caustic, PathState
from opal_diffraction.core.transport.walker import Rays


def _rays(b: int, differentials: bool = False) -> Rays:
    st = PathState.new(b, differentials)
    st.nd = np.arange(b, dtype=np.int8)
    st.pdf = np.linspace(0.1, 1.0, b).astype(np.float32)
    st.caustic = (np.arange(b) % 3).astype(np.int8)
    if differentials:
        st.rd = np.arange(b * 15, dtype=np.float32).reshape(b, 5, 3)
    z = np.zeros((b, 3), np.float32)
    return Rays(z, z, np.arange(b, dtype=np.int64), None, None, np.zeros(b, np.int32), np.zeros(b), st)


def test_new_state_has_every_field_with_its_type():
    st = PathState.new(4, differentials=True)
    types = {f.name: getattr(st, f.name).dtype for f in dataclasses.fields(st)}
    assert types == {"nd": np.int8, "diffuse": np.int16, "glossy": np.int16, "transmission": np.int16,
                     "pdf": np.float32, "caustic": np.int8, "final": bool, "seen": bool, "split": np.float32,
                     "pid": np.uint32, "sid": np.uint32, "rd": np.float32}
    assert (st.split == 1).all() and (st.caustic == Caustic.NONE).all() and st.rd.shape == (4, 5, 3)
    assert PathState.new(4).rd is None


def test_take_gathers_rows_and_concat_joins_them():
    rays = _rays(6, differentials=True)
    sub = rays.take(np.array([4, 1]))
    np.testing.assert_array_equal(sub.state.nd, [4, 1])
    np.testing.assert_array_equal(sub.state.rd, rays.state.rd[[4, 1]])
    assert sub.differentials is sub.state.rd
    joined = Rays.concat(sub, rays.take(np.array([0])))
    np.testing.assert_array_equal(joined.state.caustic, [1, 1, 0])
    np.testing.assert_array_equal(joined.state.pdf, rays.state.pdf[[4, 1, 0]])


def test_moved_rays_share_arrays_until_a_field_is_reassigned():
    rays = _rays(3)
    out = rays.moved(rays.o, rays.d, None)
    assert out.state is not rays.state and out.state.nd is rays.state.nd
    out.state.nd = out.state.nd + 1
    np.testing.assert_array_equal(rays.state.nd, [0, 1, 2])
    np.testing.assert_array_equal(out.state.nd, [1, 2, 3])


def test_populations_with_different_state_do_not_join():
    with pytest.raises(ValueError):
        Rays.concat(_rays(2, differentials=True), _rays(2))
    plain = dataclasses.replace(_rays(2), state=None)
    with pytest.raises(ValueError):
        Rays.concat(plain, _rays(2))

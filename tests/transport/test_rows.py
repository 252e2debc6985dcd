"""core/transport/rows.py: subsets of Rays, Hit and PathState gathered when a field is first read
hold exactly the rows an eager gather holds, along chains of subsets, joins and copies."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from opal_diffraction.core.transport.path_state import PathState
from opal_diffraction.core.transport.walker import Hit, Rays, _concat_all

RAY_FIELDS = ("o", "d", "pix", "w", "lam", "depth", "u_lam")
STATE_FIELDS = tuple(f.name for f in dataclasses.fields(PathState))


def _state(rng, b, rd=True):
    st = PathState.new(b, differentials=rd)
    st.nd = rng.integers(0, 3, b).astype(np.int8)
    st.pdf = rng.random(b).astype(np.float32)
    st.pid = rng.integers(0, 1000, b).astype(np.uint32)
    if rd:
        st.rd = rng.random((b, 5, 3)).astype(np.float32)
    return st


def _rays(rng, b, mono=True, rd=True):
    return Rays(rng.random((b, 3)).astype(np.float32), rng.random((b, 3)).astype(np.float32), rng.permutation(b),
                rng.random(b).astype(np.float32) if mono else rng.random((b, 7)).astype(np.float32),
                rng.integers(0, 7, b) if mono else None, rng.integers(0, 5, b).astype(np.int32), rng.random(b),
                _state(rng, b, rd))


def _hit(rng, b, flat):
    ng = rng.random((b, 3)).astype(np.float32)
    ns = ng if flat else rng.random((b, 3)).astype(np.float32)
    return Hit(rng.random((b, 3)).astype(np.float32), ng, ns, rng.random(b).astype(np.float32), rng.random(b) < 0.5,
               rng.integers(0, 4, b), rng.random(b).astype(np.float32), rng.integers(0, 50, b),
               rng.random(b).astype(np.float32), rng.random(b).astype(np.float32))


def _arrays(obj, names):
    return {k: getattr(obj, k) for k in names}


def _same(a: dict, b: dict):
    assert a.keys() == b.keys()
    for k in a:
        if a[k] is None or b[k] is None:
            assert a[k] is None and b[k] is None, k
        else:
            assert a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k]), k


def _masks(rng, b):
    yield np.ones(b, bool)
    yield np.zeros(b, bool)
    for p in (0.1, 0.5, 0.9):
        yield rng.random(b) < p
    yield rng.integers(0, b, b // 2)  # indices, with repeats


@pytest.mark.parametrize("mono", [True, False])
def test_chains_of_subsets_hold_the_eager_rows(mono):
    rng = np.random.default_rng(1)
    b = 97
    rays = _rays(rng, b, mono)
    eager = {k: v for k, v in _arrays(rays, RAY_FIELDS).items()}
    eager_st = _arrays(rays.state, STATE_FIELDS)
    for m1 in _masks(rng, b):
        r1 = rays.take(m1)
        i1 = np.arange(b)[m1] if m1.dtype == bool else m1
        for m2 in _masks(rng, len(r1)):
            r2 = r1.take(m2)
            i2 = i1[m2]
            assert len(r2) == len(i2)
            _same(_arrays(r2, RAY_FIELDS), {k: None if v is None else v[i2] for k, v in eager.items()})
            _same(_arrays(r2.state, STATE_FIELDS), {k: None if v is None else v[i2] for k, v in eager_st.items()})
        # the middle subset, read after its child: the same rows too
        _same(_arrays(r1, RAY_FIELDS), {k: None if v is None else v[i1] for k, v in eager.items()})


def test_a_field_is_gathered_only_when_read():
    rng = np.random.default_rng(2)
    rays = _rays(rng, 50)
    sub = rays.take(rng.random(50) < 0.5).take(np.array([0, 2, 3]))
    assert "d" not in sub.__dict__ and "pdf" not in sub.state.__dict__
    d = sub.d
    assert sub.__dict__["d"] is d and sub.d is d  # kept: read once
    assert "o" not in sub.__dict__


def test_a_subset_keeps_the_rows_of_when_it_was_taken():
    """Fields reassigned on the parent afterwards (the walk's rule for changing a field, the
    weights included) leave a subset as it was taken."""
    rng = np.random.default_rng(3)
    rays = _rays(rng, 40, mono=False)
    idx = np.array([1, 5, 7, 30])
    want_w, want_pdf, want_d = rays.w[idx].copy(), rays.state.pdf[idx].copy(), rays.d[idx].copy()
    sub = rays.take(idx)
    rays.state.pdf = np.zeros(40, np.float32)
    rays.d = np.zeros((40, 3), np.float32)
    rays.w = rays.w * 2
    np.testing.assert_array_equal(sub.w, want_w)
    np.testing.assert_array_equal(sub.state.pdf, want_pdf)
    np.testing.assert_array_equal(sub.d, want_d)


@pytest.mark.parametrize("flat", [True, False])
def test_flat_hits_keep_one_normal_array(flat):
    rng = np.random.default_rng(4)
    hit = _hit(rng, 60, flat)
    names = tuple(f.name for f in dataclasses.fields(Hit))
    eager = _arrays(hit, names)
    i1 = np.flatnonzero(rng.random(60) < 0.6)
    i2 = np.array([0, 3, 4])
    h = hit.take(i1).take(i2)
    assert (h.ns is h.ng) == flat
    _same(_arrays(h, names), {k: v[i1][i2] for k, v in eager.items()})
    h2 = hit.take(i1)
    h2.ng  # gathered first, then a subset of it
    h3 = h2.take(i2)
    assert (h3.ns is h3.ng) == flat


def test_joins_keep_carried_fields_pending_and_hold_the_rows_in_order():
    rng = np.random.default_rng(5)
    b = 80
    rays = _rays(rng, b)
    eager = _arrays(rays, RAY_FIELDS)
    eager_st = _arrays(rays.state, STATE_FIELDS)
    m = rng.random(b) < 0.4
    a, c = rays.take(m), rays.take(~m)
    a = a.moved(a.o + 1, a.d, a.w)  # a bounce: o, d, w, depth new; the rest carried
    a.state.pdf = np.full(len(a), 7, np.float32)
    c.pix  # gathered in one part only: concatenated
    j = _concat_all([a, c, a])
    order = np.concatenate([np.flatnonzero(m), np.flatnonzero(~m), np.flatnonzero(m)])
    assert len(j) == len(order)
    assert "u_lam" not in j.__dict__ and "sid" not in j.state.__dict__  # still pending: one gather when read
    want = {k: v[order] for k, v in eager.items()}
    want["o"] = want["o"] + np.concatenate([np.ones(m.sum()), np.zeros((~m).sum()), np.ones(m.sum())])[:, None] \
        .astype(np.float32)
    want["depth"] = want["depth"] + np.concatenate([np.ones(m.sum(), int), np.zeros((~m).sum(), int),
                                                    np.ones(m.sum(), int)]).astype(np.int32)
    _same(_arrays(j, RAY_FIELDS), want)
    want_st = {k: None if v is None else v[order] for k, v in eager_st.items()}
    want_st["pdf"] = np.where(np.concatenate([np.ones(m.sum()), np.zeros((~m).sum()), np.ones(m.sum())]) > 0,
                              np.float32(7), want_st["pdf"]).astype(np.float32)
    _same(_arrays(j.state, STATE_FIELDS), want_st)
    # and a subset of the join
    k = np.array([0, len(j) - 1, 3])
    _same(_arrays(j.take(k), RAY_FIELDS), {f: v[k] for f, v in want.items()})


def test_joining_white_and_mono_rays_or_different_state_fails():
    rng = np.random.default_rng(6)
    with pytest.raises(ValueError):
        Rays.concat(_rays(rng, 5, mono=True), _rays(rng, 5, mono=False))
    with pytest.raises(ValueError):
        Rays.concat(_rays(rng, 5, rd=True), _rays(rng, 5, rd=False))


def test_a_copy_shares_what_either_gathers():
    rng = np.random.default_rng(7)
    st = _state(rng, 30).take(np.array([3, 1, 2]))
    cp = st.copy()
    assert cp.nd is st.nd  # gathered once for both
    cp.pdf = np.zeros(3, np.float32)  # reassigned on the copy only
    np.testing.assert_array_equal(st.pdf, _state(np.random.default_rng(7), 30).pdf[[3, 1, 2]])


@dataclasses.dataclass
class _Tagged(PathState):
    tag: np.ndarray | None = None  # a subclass's field with a class-level default


def test_a_path_state_subclass_carries_its_fields():
    rng = np.random.default_rng(8)
    base = _state(rng, 20)
    st = _Tagged(*[getattr(base, k) for k in STATE_FIELDS], tag=np.arange(20))
    sub = st.take(np.array([4, 2])).take(np.array([1]))
    assert type(sub) is _Tagged and sub.tag.tolist() == [2] and sub.nd.tolist() == [base.nd[2]]
    j = PathState.join([sub, st.take(np.array([5]))])
    assert type(j) is _Tagged and j.tag.tolist() == [2, 5] and j.pdf.tolist() == base.pdf[[2, 5]].tolist()
    untagged = _Tagged(*[getattr(base, k) for k in STATE_FIELDS])
    assert untagged.take(np.array([0])).tag is None


def test_russian_roulette_reweights_into_a_new_array():
    """The eye pass's roulette (integrators/eye/continuation.py) and the light pass's give the
    survivors new weights without writing into the array a pending subset may still gather."""
    from types import SimpleNamespace

    from opal_diffraction.core.integrators.eye.continuation import russian_roulette

    rng = np.random.default_rng(5)
    rays = _rays(rng, 64, mono=False)
    rays.w = (rays.w * np.float32(0.3)).astype(np.float32)  # throughput < 1: roulette applies
    rays.depth = np.full(64, 5, np.int32)
    rays.state.final = np.zeros(64, bool)
    rays.state.split = np.ones(64, np.float32)
    idx = np.arange(0, 64, 3)
    before = rays.w[idx].copy()
    sub = rays.take(idx)  # pending until read
    ok = russian_roulette(SimpleNamespace(limits=(100, 100, 100, 100)), rays, np.random.default_rng(1))
    assert 0 < ok.sum() < 64 and not np.array_equal(rays.w[idx], before)  # survivors were reweighted
    np.testing.assert_array_equal(sub.w, before)

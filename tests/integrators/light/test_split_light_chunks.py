"""The light pass's SPLIT dispersion in chunks (docs/physics.md section 2.6, "SPLIT in chunks").

A batch's white paths are walked in pieces of ``SPLIT_CHUNK_RAYS / n`` paths, so that the mono
paths SPLIT makes at the prism (n per white path) never exceed ``SPLIT_CHUNK_RAYS`` at once. The
pieces draw the batch's random stream one after another, so the map is another sample of the same
estimator, not the same numbers: the tests check the bound (the ray caster never sees more rays
than a piece may hold, while one piece per batch does) and that the caustic is the same in
expectation (paired t-tests over independent batches, per wavelength band and position on the
wall, Bonferroni over the bins).
"""

import numpy as np
import pytest
from scipy import stats

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.transport import wavelengths
from opal_diffraction.core.transport.elements import IlluminationMap
from opal_diffraction.core.integrators.light.light_pass import LightWork
from opal_diffraction.core.integrators.light.walker import LightBatch, trace_batch
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings

PATHS = 2048  # per batch
PIECE = 256   # white paths per piece: SPLIT_CHUNK_RAYS = PIECE x n


def prism_under_lamp():
    """A dense-flint prism under a point lamp; its spectrum lands on the floor beside it."""
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
                                {"kind": "DIELECTRIC", "color": (1, 1, 1), "ior": 1.72, "dispersion": "ABBE",
                                 "abbe": 29.0}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.prism((0, 0, 0.2), side=0.3, length=0.3, axis="Y"), material=1)
    s.add_mesh(*primitives.quad((-3.0, -3.0, 0.0), (6.0, 0, 0), (0, 6.0, 0)), material=0)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (-1.5, 0.0, 1.2), "power": 100.0}])
    s.camera = Camera(width=4, height=4)
    return s


@pytest.fixture(scope="module")
def prepared():
    ctx = prepare(prism_under_lamp(), RenderSettings(light_paths=PATHS, dispersion_sampling="SPLIT",
                                                     element_size=0.05, seed=5))
    assert ctx.materials.dispersive.any()
    return ctx


def one_batch(ctx, batch: int, piece_rays: int, seen=None):
    """The caustic map (E, n) of batch ``batch`` with SPLIT_CHUNK_RAYS = ``piece_rays``; the ray
    caster's call sizes appended to ``seen``."""
    work = LightWork.of(ctx)
    illum = IlluminationMap.empty(work.layout, ctx.grid.n)
    old, intersect = wavelengths.SPLIT_CHUNK_RAYS, ctx.accel.intersect
    wavelengths.SPLIT_CHUNK_RAYS = piece_rays
    if seen is not None:
        ctx.accel.intersect = lambda o, d, *a, **k: (seen.append(len(o)), intersect(o, d, *a, **k))[1]
    try:
        trace_batch(ctx, LightBatch(0, batch, 0, PATHS), illum, None)
    finally:
        wavelengths.SPLIT_CHUNK_RAYS = old
        if seen is not None:
            del ctx.accel.intersect
    return illum.flux.astype(np.float64), work.layout


def test_split_pieces_bound_the_rays_traced_at_once(prepared):
    n = prepared.grid.n
    whole, pieces = [], []
    one_batch(prepared, 0, 1 << 40, whole)
    flux, _ = one_batch(prepared, 0, PIECE * n, pieces)
    assert flux.sum() > 0
    # one piece per batch: the mono paths of every white path that reached the prism at once
    assert max(whole) > 2 * PIECE * n
    assert max(pieces) <= PIECE * n


def test_split_pieces_give_the_same_caustic_in_expectation(prepared):
    """Paired differences chunked - whole over J independent batches (their own streams): in every
    (wavelength band, floor strip) bin the mean difference is zero within its noise (t-test,
    J - 1 degrees of freedom), at a family-wise level of 1e-3."""
    n = prepared.grid.n
    J = 16
    maps = {"whole": [], "pieces": []}
    for j in range(J):
        for name, rays in (("whole", 1 << 40), ("pieces", PIECE * n)):
            flux, layout = one_batch(prepared, j, rays)
            maps[name].append(flux)
    # bins: 4 wavelength bands x 6 strips along x of the floor's lit elements
    tri, bu, bv = layout.barycentric_centres()
    v = np.asarray(prepared.scene.vertices, np.float64)[np.asarray(prepared.scene.triangles)[tri]]
    x = ((1 - bu - bv)[:, None] * v[:, 0] + bu[:, None] * v[:, 1] + bv[:, None] * v[:, 2])[:, 0]
    total = sum(maps["whole"]).sum(axis=1)
    lit = total > 0
    order = np.argsort(x[lit])  # strips of equal flux: edges at the flux-weighted sextiles
    cdf = np.cumsum(total[lit][order]) / total[lit].sum()
    edges = x[lit][order][np.searchsorted(cdf, np.arange(1, 6) / 6)]
    strip = np.searchsorted(edges, x, side="right")
    band = np.minimum(np.arange(n) * 4 // n, 3)

    def binned(f):
        out = np.zeros((6, 4))
        np.add.at(out, (strip[:, None], band[None, :]), np.where(lit[:, None], f, 0.0))
        return out.ravel()

    a = np.array([binned(f) for f in maps["pieces"]])
    b = np.array([binned(f) for f in maps["whole"]])
    used = b.mean(axis=0) > 0  # strips can coincide where one element holds much of the flux
    assert used.sum() >= 12
    a, b = a[:, used], b[:, used]
    d = a - b
    se = d.std(axis=0, ddof=1) / np.sqrt(J)
    assert (se > 0).all()  # the pieces draw other numbers: not the same map
    t = d.mean(axis=0) / se
    crit = stats.t.ppf(1 - 1e-3 / (2 * d.shape[1]), J - 1)
    assert np.abs(t).max() < crit, (t, crit)
    # and the total flux agrees within its noise, which is small enough that a piece lost or
    # traced twice (1/8 of the batch's flux) would fail
    tot_d = d.sum(axis=1)
    se_tot = tot_d.std(ddof=1) / np.sqrt(J)
    assert abs(tot_d.mean()) < 4 * se_tot
    assert 4 * se_tot < b.sum(axis=1).mean() / 8

"""The world map seen by escaping eye rays (core/integrators/eye/emission.py: escaped, world_seen)
on the kernels (lookup, _world_contrib_kernel, one deposit of all vertex counts) against the NumPy
chain run on the kernels (the same bits) and on the reference (the uplift's last bits)."""

from types import SimpleNamespace

import numpy as np
import pytest

from opal_diffraction.core.integrators.eye import emission
from opal_diffraction.core.integrators.eye.next_event import power_heuristic
from opal_diffraction.core.integrators.eye.tile_output import TileOutput
from opal_diffraction.core.lights.environment import EnvironmentMap
from opal_diffraction.core.spectral.spectrum import SpectralConverter
from opal_diffraction.core.transport.path_state import PathState
from opal_diffraction.core.transport.walker import Rays
from opal_diffraction.core.util import jit

pytestmark = pytest.mark.skipif(not jit.AVAILABLE, reason=jit.UNAVAILABLE_REASON or "numba missing")

P = 23
CONV = SpectralConverter()
N = CONV.grid.n


def _context(rng, rotated=False, interpolation="LINEAR"):
    rgb = (rng.uniform(0, 3, (9, 16, 3)) ** 2).astype(np.float32)
    rgb[2] = 0  # a black row: zero density there
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0] if rotated else None
    env = EnvironmentMap(rgb, rot, interpolation)
    prepared = SimpleNamespace(environment=env, conv=CONV)
    return SimpleNamespace(prepared=prepared, caustics_cover_lights=False, soft_suns=[], n=N)


def _rays(rng, b, kind):
    d = rng.normal(size=(b, 3))
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    state = PathState.new(b)
    state.nd[:] = rng.integers(0, 4, b)
    state.pdf[:] = np.where(rng.random(b) < 0.3, 0, rng.uniform(0, 3, b))  # 0: camera or specular
    state.pdf[:3] = [np.inf, 1e30, np.nan][:b]
    lam = w = None
    if kind == "mono":
        lam, w = rng.integers(0, N, b), rng.random(b).astype(np.float32)
    elif kind == "white":
        w = rng.random((b, N)).astype(np.float32)
    z = np.zeros((b, 3), np.float32)
    return Rays(z, d, rng.integers(0, P, b).astype(np.int64), w, lam, np.zeros(b, np.int64), np.zeros(b), state)


def _chain(c, out, rays, film):
    """world_seen's NumPy lines (the chain the kernel replaces), on whatever path is set."""
    env = c.prepared.environment
    spectra = CONV.illuminant_from_rgb(env.radiance_rgb(rays.d)).astype(np.float32)
    spectra *= power_heuristic(rays.state.pdf, env.pdf(rays.d).astype(np.float32))[:, None]
    contrib = rays.weighted(spectra) if rays.lam is None else rays.w * spectra[np.arange(len(rays)), rays.lam]
    out.accumulate(rays, contrib, film)


def _films(out):
    return {"film": out.film, **out.parts}


@pytest.mark.parametrize("kind", ["unit", "white", "mono"])
@pytest.mark.parametrize("rotated", [False, True])
def test_escaped_is_the_chain_on_the_kernels_bit_for_bit(kind, rotated):
    rng = np.random.default_rng(3 + rotated)
    c = _context(rng, rotated)
    rays = _rays(rng, 900, kind)
    want = TileOutput(P, N)
    got = TileOutput(P, N)
    with jit.kernel_mode("auto"):
        for nd in np.unique(rays.state.nd):  # escaped's loop before the kernels
            sub = rays.take(rays.state.nd == nd)
            _chain(c, want, sub, want.light_film(min(int(nd), 2)))
        emission.escaped(c, got, rays, None)
    fw, fg = _films(want), _films(got)
    assert list(fg) == list(fw)
    for k in fw:
        np.testing.assert_array_equal(fg[k].view(np.uint32), fw[k].view(np.uint32))
    assert fg["film"].any()


@pytest.mark.parametrize("kind", ["unit", "white", "mono"])
@pytest.mark.parametrize("interpolation", ["LINEAR", "CLOSEST"])
def test_escaped_and_world_seen_match_the_reference(kind, interpolation):
    rng = np.random.default_rng(7)
    c = _context(rng, True, interpolation)
    rays = _rays(rng, 700, kind)
    outs = {}
    for mode in ("numpy", "auto"):
        out = TileOutput(P, N)
        with jit.kernel_mode(mode):
            emission.escaped(c, out, rays, None)
            emission.world_seen(c, out, rays, out.caustics)
        outs[mode] = _films(out)
    assert list(outs["auto"]) == list(outs["numpy"])
    for k, ref in outs["numpy"].items():
        # the uplift kernel agrees with NumPy's to a few float64 ulps (tests/util/test_kernels.py):
        # rounded to float32 that is at most one float32 ulp (6e-8) per contribution, and the
        # deposits sum in the same order
        np.testing.assert_allclose(outs["auto"][k], ref, rtol=1e-6, atol=1e-6 * ref.max())
    assert outs["auto"]["caustics"].any()


def test_world_seen_with_no_rays_adds_nothing():
    rng = np.random.default_rng(1)
    c = _context(rng)
    out = TileOutput(P, N)
    with jit.kernel_mode("auto"):
        emission.world_seen(c, out, _rays(rng, 0, "white"), out.film)
        emission.escaped(c, out, _rays(rng, 0, "mono"), None)
    assert not out.film.any() and not out.parts

"""Thin films in the GGX lobes' Fresnel (core/materials/bsdf.py, docs/physics.md section 2.8).

A microfacet lobe is D G F / (4 cos cos): with a film only F changes, to the film's reflectance
at the microfacet angle (wo . h). So the filmed lobe divided by the same lobe without the film
is R_film(wo . h, lambda) / F(wo . h, lambda) for a reflection and (1 - R_film) / (1 - F) for a
refraction, with R_film from the independent characteristic matrix (tests/thin_film_matrix.py)
over the conductor of Gulbrandsen's n, k (written here) or the glass.
"""

import math

import numpy as np

from opal_diffraction.core.materials import bsdf as B
from opal_diffraction.core.materials.spectra import prepare_materials
from opal_diffraction.core.scene.model import Materials
from opal_diffraction.core.spectral.optics import fresnel_dielectric
from opal_diffraction.core.spectral.spectrum import SpectralConverter, WavelengthGrid

from thin_film_matrix import matrix_unpolarised

CONV = SpectralConverter(WavelengthGrid(400.0, 700.0, 30.0))
FILM = {"thin_film_thickness": 380.0, "thin_film_ior": 1.42}


def _pair(row):
    """Prepared materials: row 0 with the film, row 1 the same without."""
    return prepare_materials(Materials.from_list([{**row, **FILM}, row]), CONV)


def _directions(n, rng, transmit=False):
    def unit(v):
        return v / np.linalg.norm(v, axis=1, keepdims=True)
    wo = unit(rng.normal(size=(n, 3)) * [0.5, 0.5, 0.3] + [0, 0, 1]).astype(np.float32)
    wi = unit(rng.normal(size=(n, 3)) * [0.5, 0.5, 0.3] + [0, 0, -1 if transmit else 1]).astype(np.float32)
    return wo, wi


def _gulbrandsen(r, g):
    r = min(r, 0.999)
    n = g * (1 - r) / (1 + r) + (1 - g) * (1 + math.sqrt(r)) / (1 - math.sqrt(r))
    return complex(n, math.sqrt(max((r * (n + 1) ** 2 - (n - 1) ** 2) / (1 - r), 0.0)))


def test_rough_metal_lobe_takes_the_film_reflectance():
    pm = _pair({"kind": "MIRROR", "color": (0.95, 0.7, 0.3), "roughness": 0.4, "metallic": 1.0,
                "conductor_fresnel": "F82_TINT", "specular_tint": (1.0, 0.9, 0.8)})
    rng = np.random.default_rng(1)
    wo, wi = _directions(6, rng)
    ns = np.tile(np.float32([0, 0, 1]), (6, 1))
    f = {}
    for row in (0, 1):
        p = B.params_from_materials(pm, np.full(6, row), np.ones(6, bool))
        f[row] = B.evaluate(p, wo, wi, ns, ns)[0].astype(np.float64)
    h = wo + wi
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    coh = np.sum(wo * h, axis=1)
    base = pm.reflectance[1].astype(np.float64)
    tint = pm.specular_tint[1].astype(np.float64)
    b = B.f82_b(base[None, :], np.minimum(tint, 1.0)[None, :])
    f82 = B.fresnel_f82(np.array([1 / 7]), base[None, :], b)[0]
    plain = B.fresnel_f82(coh, np.tile(base, (6, 1)), np.tile(b, (6, 1))).astype(np.float64)
    wl = CONV.grid.wavelengths
    for i in range(6):
        film = np.array([matrix_unpolarised(1.0, FILM["thin_film_ior"], FILM["thin_film_thickness"],
                                            _gulbrandsen(base[k], f82[k]), math.acos(min(coh[i], 1.0)), wl[k])[0]
                         for k in range(len(wl))])
        np.testing.assert_allclose(f[0][i], f[1][i] * film / plain[i], rtol=2e-4, atol=1e-7)
    assert np.ptp(f[0] / f[1]) > 0.05  # the film shows


def test_rough_glass_lobes_take_the_film_reflectance_and_transmittance():
    n = 1.5
    pm = _pair({"kind": "DIELECTRIC", "color": (1, 1, 1), "ior": n, "roughness": 0.3, "transmission": 1.0})
    rng = np.random.default_rng(2)
    ns = np.tile(np.float32([0, 0, 1]), (40, 1))
    wl = CONV.grid.wavelengths
    for transmit in (False, True):
        wo, wi = _directions(40, rng, transmit)
        for lam in range(0, len(wl), 4):
            lam_v = np.full(40, lam)
            fa = B.evaluate(B.params_from_materials(pm, np.zeros(40, int), np.ones(40, bool), lam_v), wo, wi, ns, ns)[0]
            fb = B.evaluate(B.params_from_materials(pm, np.ones(40, int), np.ones(40, bool), lam_v), wo, wi, ns, ns)[0]
            h = (n * wi + wo) if transmit else (wo + wi)
            h /= np.linalg.norm(h, axis=1, keepdims=True)
            h *= np.sign(h[:, 2:3])
            coh = np.sum(wo * h, axis=1).astype(np.float64)
            plain = fresnel_dielectric(coh, np.full(40, n))[0]
            film = np.array([matrix_unpolarised(1.0, FILM["thin_film_ior"], FILM["thin_film_thickness"], n,
                                                math.acos(min(c, 1.0)), wl[lam])[0] for c in coh])
            ok = fb[:, 0] > 1e-6
            with np.errstate(all="ignore"):
                ratio = (1 - film) / (1 - plain) if transmit else film / plain
            assert ok.sum() >= 5
            np.testing.assert_allclose(fa[ok, 0], fb[ok, 0] * ratio[ok], rtol=1e-3)


def test_filmed_params_take_the_numpy_reference_and_sample_consistently():
    """Sampling a filmed rough metal: weight = f cos / pdf of evaluate at the sampled direction."""
    pm = _pair({"kind": "MIRROR", "color": (0.9, 0.9, 0.9), "roughness": 0.5, "metallic": 1.0,
                "conductor_fresnel": "F82_TINT"})
    rng = np.random.default_rng(3)
    wo, _ = _directions(64, rng)
    ns = np.tile(np.float32([0, 0, 1]), (64, 1))
    p = B.params_from_materials(pm, np.zeros(64, int), np.ones(64, bool))
    assert not B._kernel_fits(p)
    wi, weight, pdf, flags = B.sample(p, wo, ns, ns, rng.random((64, 3)).astype(np.float32))
    ok = flags != 0
    fcos, pdf_e = B.evaluate(p, wo, wi[ok], ns[ok], ns[ok]) if ok.all() else B.evaluate(
        p.take(np.flatnonzero(ok)), wo[ok], wi[ok], ns[ok], ns[ok])
    np.testing.assert_allclose(weight[ok], fcos / pdf_e[:, None], rtol=2e-3, atol=1e-6)

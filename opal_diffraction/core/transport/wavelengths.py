"""Wavelength sampling at a dispersive interface: which wavelengths a white ray becomes.

A white ray carries the whole grid (n wavelengths); at a dispersive glass its directions part,
so it becomes mono rays (core/transport/walker.py ``SpecularWalker.split_white``). SAMPLE draws K of them (K: the
setting ``dispersion_branches``)
and weights each w_k / (K p_k), an unbiased estimator of the exact sum over the grid that SPLIT
traces (docs/physics.md section 2.6). Three things make its colour noise smaller than a uniform
one-wavelength pick:

- **importance by the image's sensitivity** (``dispersion_importance``; pbrt-v4's ``SampleVisibleWavelengths`` idea,
  src/pbrt/util/spectrum.h, with the pdf derived from our own film instead of its cosh^2 fit):
  a unit sample at wavelength k adds w_k x rgb_weights[k] to the linear Rec.709 image, so the
  pdf that minimises the summed variance of R, G and B for a ray of weight w is
  p_k ~ w_k sqrt(sum_c rgb_weights[k, c]^2) (the L2 norm of the Rec.709 matching functions);
  camera rays (unit weights) use the white illuminant's spectrum for w (what most lights emit).
  A uniform share ``DEFENSIVE`` is mixed in so every wavelength stays reachable (the spectral
  EXR is a film too) and no weight exceeds 1 / DEFENSIVE times a uniform pick's;
- **stratification**: the K numbers of a ray are its pixel's low-discrepancy number u (the
  Sobol-Burley dimension of core/camera.pixel_samples) rotated by j / K (pbrt-v4's hero
  wavelength rotation, Wilkie et al. 2014), inverted through the pdf's CDF;
- **reflection stays white** (``dispersion_white_reflection``): a smooth dispersive surface reflects every
  wavelength the same way, so the reflect / refract choice is made once for the white ray, with
  probability P = sum_k p_k F_k (F_k the Fresnel reflectance at wavelength k, p the importance
  above); a reflected ray goes on white with weight w_k F_k / P, a refracted one becomes mono rays
  drawn from p with weights w_k (1 - F_k) / ((1 - P) K p_k): the facets' white
  reflections of the lights keep their colour exact, only light that enters the glass is split.

The three choices are RenderSettings fields (core/scene/settings.py), passed down as arguments, so
benchmarks/bench_dispersion.py can measure each against the others.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["DEFENSIVE", "sensitivity", "importance", "sample_indices", "rotated", "draw"]

#: The uniform share of the importance pdf.
DEFENSIVE = 0.1


@lru_cache(maxsize=16)
def _sensitivity(key) -> tuple[np.ndarray, np.ndarray]:
    from ..spectral.spectrum import SpectralConverter, WavelengthGrid

    conv = SpectralConverter(WavelengthGrid(*key))
    s = np.sqrt((conv.rgb_weights.astype(np.float64) ** 2).sum(axis=1))
    return s, s * conv.white_illuminant


def sensitivity(grid, white: bool = False) -> np.ndarray:
    """(n,) float64: the L2 norm of the Rec.709 matching functions per grid wavelength (``white``:
    times the white illuminant, the sensitivity of the image to a unit-weight camera ray)."""
    s, sw = _sensitivity((float(grid.lambda_min), float(grid.lambda_max), float(grid.step)))
    out = sw if white else s
    if len(out) != grid.n:
        raise ValueError(f"grid of {grid.n} wavelengths, sensitivity of {len(out)}")
    return out


def importance(grid, w: np.ndarray | None, b: int, by_sensitivity: bool) -> np.ndarray:
    """(B, n) float64 unnormalised importance of each wavelength for B rays of weights ``w``
    ((B, n), or None for unit weights): w_k x sensitivity_k, or w_k (1 for unit weights) without
    ``by_sensitivity`` (the setting ``dispersion_importance``)."""
    n = grid.n
    if not by_sensitivity:
        return np.ones((b, n)) if w is None else np.asarray(w, np.float64)
    if w is None:
        return np.broadcast_to(sensitivity(grid, white=True), (b, n))
    return np.asarray(w, np.float64) * sensitivity(grid)[None, :]


def _defended(q: np.ndarray, by_sensitivity: bool, support: np.ndarray | None = None) -> np.ndarray:
    """Rows of q (B, n) >= 0 normalised to pdfs, mixed (``by_sensitivity``: q is ``importance``'s)
    with DEFENSIVE x uniform over ``support`` (B, n) bool (default q > 0: where the estimated
    spectrum can be non-zero)."""
    total = q.sum(axis=1, keepdims=True)
    p = q / np.where(total > 0, total, 1.0)
    if by_sensitivity and DEFENSIVE > 0:
        support = q > 0 if support is None else support
        cnt = support.sum(axis=1, keepdims=True)
        p = (1.0 - DEFENSIVE) * p + DEFENSIVE * support / np.maximum(cnt, 1)
    return p


def rotated(u: np.ndarray, k: int) -> np.ndarray:
    """(B, k) numbers u + j / k mod 1, j = 0..k-1 (the hero wavelength and its rotations)."""
    return np.mod(np.asarray(u, np.float64)[:, None] + np.arange(k)[None, :] / k, 1.0)


def sample_indices(p: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Indices (B, k) drawn from the rows of the pdfs p (B, n) by inverting their CDFs at u (B, k)."""
    cdf = np.cumsum(p, axis=1)
    total = cdf[:, -1:]
    lam = np.empty(u.shape, np.int64)
    for j in range(u.shape[1]):  # K columns (a handful)
        lam[:, j] = (cdf < u[:, j:j + 1] * total).sum(axis=1)
    return np.minimum(lam, p.shape[1] - 1)


def draw(grid, w: np.ndarray | None, u: np.ndarray, k: int, by_sensitivity: bool, q_extra: np.ndarray | None = None):
    """Mono wavelengths for B white rays of weights ``w`` (None: unit) with numbers ``u`` (B,).

    ``k``: children per ray (the setting ``dispersion_branches``); ``by_sensitivity``: the pdf
    follows ``importance`` (the setting ``dispersion_importance``). ``q_extra`` (B, n): a factor
    of the target distribution beyond the weight (the transmitted share 1 - F_k at a refraction),
    which the weights include too. Returns (parent (M,), lam (M,), weight (M,) float64): each
    ray's K = ``k`` children with weight w_k q_k / (K p_k), rays whose target is zero everywhere
    left out.
    """
    k = int(k)
    b, n = len(u), grid.n
    target = np.ones((b, n)) if w is None else np.asarray(w, np.float64)
    if q_extra is not None:
        target = target * q_extra
    q = importance(grid, w, b, by_sensitivity)
    if q_extra is not None:
        q = q * q_extra
    live = q.sum(axis=1) > 0
    p = _defended(q[live], by_sensitivity, target[live] > 0)
    lam = sample_indices(p, rotated(np.asarray(u)[live], k))
    parent = np.repeat(np.flatnonzero(live), k)
    lam = lam.ravel()
    rows = np.repeat(np.arange(int(live.sum())), k)
    weight = target[live][rows, lam] / (k * p[rows, lam])
    return parent, lam, weight


def split_at_glass(walker, rays, hit, rng, u=None):
    """White ``rays`` at dispersive hits ``hit`` (smooth or rough glass) -> (mono children at the
    hit or None, their hits, white rays reflected by smooth glass or None).

    SPLIT, or the setting ``dispersion_white_reflection`` off: ``walker.split_white`` (children at the hit, which take their
    own Fresnel choice). Otherwise smooth glass chooses reflect / refract for the white ray (module
    docstring): reflected rays go on white (returned, bounce counted), refracted ones become mono
    rays already refracted at their wavelengths, handed to ``walker.spawn`` (the walk traces
    them with the mono population); rough glass still splits at the hit. ``u`` (B,): the
    numbers of the reflect / refract choice (None: drawn from ``rng``).
    """
    from ..materials.spectra import DIELECTRIC
    from ..spectral.optics import fresnel_dielectric, reflect, refract
    from ..sampling import footprint

    prepared = walker.prepared
    settings = prepared.settings
    if settings.dispersion_sampling == "SPLIT" or not settings.dispersion_white_reflection:
        return (*walker.split_white(rays, hit, rng), None)
    smooth = prepared.materials.kind[hit.mat] == DIELECTRIC
    children = child_hits = None
    if u is None:  # the reflect / refract choice's numbers, one per ray (the eye pass: its sampler's)
        u = rng.random(len(rays))
    if not smooth.all():
        rough = ~smooth
        children, child_hits = walker.split_white(rays.take(rough), hit.take(rough), rng)
        rays, hit, u = rays.take(smooth), hit.take(smooth), u[smooth]
    if not len(rays):
        return children, child_hits, None
    grid = prepared.grid
    b = len(rays)
    ior = prepared.materials.ior[hit.mat].astype(np.float64)  # (B, n)
    eta = np.where(hit.front[:, None], 1.0 / ior, ior)
    ns = walker.specular_normal(rays, hit)
    cos_s = hit.cos_i if ns is hit.ng else -np.einsum("ij,ij->i", rays.d, ns)
    fr, _ = fresnel_dielectric(np.abs(np.asarray(cos_s, np.float64))[:, None],
                               np.where(hit.front[:, None], ior, 1.0 / ior))  # (B, n)
    wt = walker.tinted_weight(rays, hit)  # (B, n) or None: the glass's tint applies to both branches
    q = importance(grid, wt, b, settings.dispersion_importance)
    qs = q.sum(axis=1)
    p_refl = np.where(qs > 0, (q * fr).sum(axis=1) / np.where(qs > 0, qs, 1.0), 1.0)
    refl = u < p_refl
    white = None
    if refl.any():
        r, h = rays.take(refl), hit.take(refl)
        nr = ns[refl]
        wr = (fr[refl] / p_refl[refl, None]).astype(np.float32)
        if wt is not None:
            wr = wr * wt[refl]
        o = h.p + h.eps[:, None] * h.ng
        white = r.moved(o.astype(np.float32), reflect(r.d, nr).astype(np.float32), wr)
        if white.differentials is not None:
            white.state.rd = footprint.reflect_differentials(r.differentials, r.o, r.d, h.p, nr)
        white = walker.after_delta(white, np.zeros(len(white), bool))
    tr = ~refl
    if tr.any():
        r, h = rays.take(tr), hit.take(tr)
        # the wavelengths from the ray's number and weight alone (not from the Fresnel factor, which
        # moves with the hit point's rounding: the image stays the same on every ray-casting backend)
        parent, lam, w = draw(grid, None if wt is None else wt[tr], r.u_lam, settings.dispersion_branches,
                              settings.dispersion_importance)
        w = w * (1.0 - fr[tr][parent, lam]) / (1.0 - p_refl[tr][parent])
        keep = w > 0  # a wavelength that cannot refract (total internal reflection) has no child
        if not keep.all():
            parent, lam, w = parent[keep], lam[keep], w[keep]
        nr = ns[tr][parent]
        d = r.d[parent]
        e = eta[tr][parent, lam].astype(np.float32)
        t_dir, _ = refract(d, nr, e)
        hp = h.take(parent)
        if ns is not hit.ng:  # refracted about ns onto the incident side: about ng instead (transport.py)
            stay = np.einsum("ij,ij->i", t_dir, hp.ng) >= 0
            if stay.any():
                t_dir[stay] = refract(d[stay], hp.ng[stay], e[stay])[0]
        side = np.where(np.einsum("ij,ij->i", t_dir, hp.ng) > 0, 1.0, -1.0).astype(np.float32)
        o = hp.p + (hp.eps * side)[:, None] * hp.ng
        state = None if r.state is None else r.state.take(parent)
        # type(r): transport.Rays, without importing the module that imports this one
        mono = type(r)(o.astype(np.float32), t_dir.astype(np.float32), r.pix[parent], w.astype(np.float32),
                    lam.astype(np.int64), r.depth[parent] + 1, r.u_lam[parent], state)
        if mono.differentials is not None:
            mono.state.rd = footprint.refract_differentials(state.rd, r.o[parent], d, hp.p, nr, t_dir, e)
        mono = walker.after_delta(mono, side < 0)
        if len(mono):
            walker.spawn(mono)
    return children, child_hits, white


#: SPLIT: the mono rays one batch of camera rays may become at most (each ray carries ~150 bytes
#: of path state through the walk); a larger batch is traced in chunks of camera rays.
SPLIT_CHUNK_RAYS = 1 << 18


def split_chunks(prepared, b: int) -> list[slice] | None:
    """Slices of a batch of ``b`` white rays (the eye pass's camera rays, the light pass's paths)
    such that SPLIT makes at most SPLIT_CHUNK_RAYS mono rays from each (None: one piece will do,
    or the scene does not split)."""
    if prepared.settings.dispersion_sampling != "SPLIT" or not bool(prepared.materials.dispersive.any()):
        return None
    per = max(1, SPLIT_CHUNK_RAYS // prepared.grid.n)
    if b <= per:
        return None
    return [slice(s, min(s + per, b)) for s in range(0, b, per)]


def merge_tiles(results):
    """The sum of eye_pass.TileResults of pieces of one batch (same pixels)."""
    from dataclasses import fields, replace

    first = results[0]
    out = {}
    for f in fields(first):
        vals = [getattr(r, f.name) for r in results]
        if all(v is None for v in vals):
            out[f.name] = None
        elif isinstance(vals[0], (int, np.integer)):
            out[f.name] = int(sum(vals))
        else:
            arrs = [v for v in vals if v is not None]
            total = arrs[0].copy()
            for v in arrs[1:]:
                total += v
            out[f.name] = total
    return replace(first, **out)

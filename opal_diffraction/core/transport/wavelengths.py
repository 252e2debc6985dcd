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

A thin film on smooth glass (docs/physics.md section 2.8) makes F_k vary over the grid as a
dispersive index does: such glass is marked dispersive, its F_k is the film's Airy reflectance
(core/materials/thin_film.py), and its batches take the NumPy lines below.

Smooth glass's white reflect / refract choice, the draw and the children's refraction run as one
numba loop per batch when kernels are on (``_glass_kernel``, core/util/jit.py): per ray one
Fresnel row, NumPy's pairwise row sums reproduced, no (B, n) temporaries; bit-identical to the
NumPy lines, which stay the reference.

The three choices are RenderSettings fields (core/scene/settings.py), passed down as arguments, so
benchmarks/bench_dispersion.py can measure each against the others.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..util.jit import kernels_enabled, njit

__all__ = ["DEFENSIVE", "sensitivity", "importance", "sample_indices", "rotated", "draw", "child_split"]

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


def child_split(state, w_child, parent, parent_w) -> None:
    """Set the mono children's ``PathState.split`` (rows of ``state``, children of the white rows
    ``parent``) so that Russian roulette judges a child by its white parent's throughput times what
    it lost since (core/integrators/eye/continuation.py): split times the child's weight over the
    parent's largest spectral weight (``parent_w`` (B, n) or None: unit weights). The pick's
    1 / (K p_k) factor is thereby divided out; any survival probability keeps the estimate
    unbiased, this one only keeps it from rouletting bright dispersed paths. ``state`` None (the
    light pass): nothing."""
    if state is None or len(parent) == 0:
        return
    wmax = np.float32(1.0) if parent_w is None else np.maximum(parent_w.max(axis=1)[parent], np.float32(1e-30))
    state.split = (state.split * (np.asarray(w_child, np.float32) / wmax)).astype(np.float32, copy=False)


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
    ns = walker.specular_normal(rays, hit)
    wt = walker.tinted_weight(rays, hit)  # (B, n) or None: the glass's tint applies to both branches
    from ..materials import thin_film

    film = thin_film.film_rows(prepared.materials, hit.mat)
    if kernels_enabled() and film is None and _fits_glass_kernel(rays, hit, ns, wt, prepared.materials.ior):
        return children, child_hits, _split_smooth_by_kernel(walker, rays, hit, ns, wt, u)
    ior = prepared.materials.ior[hit.mat].astype(np.float64)  # (B, n)
    eta = np.where(hit.front[:, None], 1.0 / ior, ior)
    cos_s = hit.cos_i if ns is hit.ng else -np.einsum("ij,ij->i", rays.d, ns)
    fr, _ = fresnel_dielectric(np.abs(np.asarray(cos_s, np.float64))[:, None],
                               np.where(hit.front[:, None], ior, 1.0 / ior))  # (B, n)
    if film is not None:  # a thin film's interference at every wavelength (docs/physics.md section 2.8)
        idx = np.flatnonzero(film)
        fr = np.array(fr)
        fr[idx] = thin_film.glass_fresnel(prepared.materials, grid.wavelengths, hit.mat[idx], hit.front[idx],
                                          np.abs(np.asarray(cos_s, np.float64))[idx], ior[idx])
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
        child_split(state, w, parent, None if wt is None else wt[tr])
        # type(r): transport.Rays, without importing the module that imports this one
        mono = type(r)(o.astype(np.float32), t_dir.astype(np.float32), r.pix[parent], w.astype(np.float32),
                    lam.astype(np.int64), r.depth[parent] + 1, r.u_lam[parent], state)
        if mono.differentials is not None:
            mono.state.rd = footprint.refract_differentials(state.rd, r.o[parent], d, hp.p, nr, t_dir, e)
        mono = walker.after_delta(mono, side < 0)
        if len(mono):
            walker.spawn(mono)
    return children, child_hits, white


def _fits_glass_kernel(rays, hit, ns, wt, ior) -> bool:
    """The arrays _glass_kernel is compiled for: float32 rows of 3 and (B, n) weights."""
    f32 = np.dtype(np.float32)
    return (len(rays) > 0 and ior.shape[1] <= 900 and all(a.dtype == f32 and a.ndim == 2 for a in (rays.d, hit.p, hit.ng, ns))
            and hit.eps.dtype == f32 and ior.dtype.kind == "f" and (wt is None or (wt.dtype == f32 and wt.ndim == 2)))


def _split_smooth_by_kernel(walker, rays, hit, ns, wt, u):
    """split_at_glass's smooth-glass lines by _glass_kernel: (white reflected rays or None); the
    refracted mono children go to ``walker.spawn``. The same operations in the same order and
    precisions as the NumPy lines (NumPy's pairwise row sums included), so the same bits."""
    from ..sampling import footprint

    prepared = walker.prepared
    s, n = prepared.settings, prepared.grid.n
    b, k = len(rays), int(s.dispersion_branches)
    flat = ns is hit.ng
    cos_s = hit.cos_i if flat else -np.einsum("ij,ij->i", rays.d, ns)
    sens = sensitivity(prepared.grid, white=wt is None) if s.dispersion_importance else np.ones(n)
    refl, wr = np.empty(b, np.bool_), np.empty((b, n), np.float32)
    rd, ro = np.empty((b, 3), np.float32), np.empty((b, 3), np.float32)
    parent, lam = np.empty(b * k, np.int64), np.empty(b * k, np.int64)
    w, e = np.empty(b * k, np.float32), np.empty(b * k, np.float32)
    t_dir, o, side = np.empty((b * k, 3), np.float32), np.empty((b * k, 3), np.float32), np.empty(b * k, np.float32)
    u = np.asarray(u, np.float64)
    m = _glass_kernel(prepared.materials.ior, hit.mat, hit.front, np.asarray(cos_s, np.float32),
                      wr if wt is None else wt, wt is not None, sens, bool(s.dispersion_importance) and DEFENSIVE > 0,
                      DEFENSIVE, u, np.asarray(rays.u_lam, np.float64), k, rays.d, ns, hit.ng, hit.p, hit.eps,
                      flat, refl, wr, rd, ro, parent, lam, w, e, t_dir, o, side)
    white = None
    if refl.any():
        idx = np.flatnonzero(refl)
        r = rays.take(idx)
        white = r.moved(ro[idx], rd[idx], wr[idx])
        if white.differentials is not None:
            white.state.rd = footprint.reflect_differentials(r.differentials, r.o, r.d, hit.p[idx], ns[idx])
        white = walker.after_delta(white, np.zeros(len(white), bool))
    if m:
        parent, t_dir, side = parent[:m], t_dir[:m], side[:m]
        state = None if rays.state is None else rays.state.take(parent)
        child_split(state, w[:m], parent, wt)
        mono = type(rays)(o[:m], t_dir, rays.pix.take(parent), w[:m], lam[:m], rays.depth.take(parent) + 1,
                          rays.u_lam.take(parent), state)
        if mono.differentials is not None:
            mono.state.rd = footprint.refract_differentials(state.rd, rays.o.take(parent, axis=0),
                                                            rays.d.take(parent, axis=0), hit.p.take(parent, axis=0),
                                                            ns.take(parent, axis=0), t_dir, e[:m])
        mono = walker.after_delta(mono, side < 0)
        if len(mono):
            walker.spawn(mono)
    return white


@njit
def _pairwise_block(a, lo, n):
    """NumPy's pairwise sum (its add loops' ``pairwise_sum``, as ``ndarray.sum`` along a contiguous
    row runs it) of a[lo:lo + n] for n <= 128: sequential from -0.0 below 8 terms, else eight
    interleaved partial sums."""
    if n < 8:
        res = -0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - n % 8:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit
def _pairwise_240(a, lo, n):
    """Up to 240 terms (both halves within a block): above 128 NumPy sums two halves, the first a
    multiple of 8 (numba's cache cannot reload recursive functions, so the levels are spelled out)."""
    if n <= 128:
        return _pairwise_block(a, lo, n)
    half = n // 2
    half -= half % 8
    return _pairwise_block(a, lo, half) + _pairwise_block(a, lo + half, n - half)


@njit
def _pairwise_460(a, lo, n):
    """Up to 460 terms (halves within _pairwise_240's bound)."""
    if n <= 128:
        return _pairwise_block(a, lo, n)
    half = n // 2
    half -= half % 8
    return _pairwise_240(a, lo, half) + _pairwise_240(a, lo + half, n - half)


@njit
def _pairwise(a, lo, n):
    """NumPy's pairwise sum of a[lo:lo + n] for n <= 900 (_fits_glass_kernel keeps grids within it)."""
    if n <= 128:
        return _pairwise_block(a, lo, n)
    half = n // 2
    half -= half % 8
    return _pairwise_460(a, lo, half) + _pairwise_460(a, lo + half, n - half)


@njit
def _fresnel64(c, e):
    """spectral.optics.fresnel_dielectric's lines for one float64 cosine and relative index."""
    if c < 0.0:
        c = 0.0
    if c > 1.0:
        c = 1.0
    sin2_t = (1.0 - c * c) / (e * e)
    t = 1.0 - sin2_t
    if t < 0.0:
        t = 0.0
    cos_t = np.sqrt(t)
    den_par = e * c + cos_t
    if den_par < 1e-30:
        den_par = 1e-30
    den_perp = c + e * cos_t
    if den_perp < 1e-30:
        den_perp = 1e-30
    r_par = (e * c - cos_t) / den_par
    r_perp = (c - e * cos_t) / den_perp
    return 1.0 if sin2_t >= 1.0 else 0.5 * (r_par * r_par + r_perp * r_perp)


@njit
def _refract32(d, n, e, out):
    """spectral.optics.refract's float32 lines for one direction d (3,), normal n (3,), eta e, into out."""
    one, two = np.float32(1.0), np.float32(2.0)
    s = (d[0] * n[0] + d[1] * n[1]) + d[2] * n[2]
    c = -s
    sin2_t = e * e * max(np.float32(0.0), one - c * c)
    if sin2_t > one:  # total internal reflection: the mirror direction
        for j in range(3):
            out[j] = d[j] - two * s * n[j]
        return
    cos_t = np.sqrt(max(np.float32(0.0), one - sin2_t))
    g = e * c - cos_t
    for j in range(3):
        out[j] = e * d[j] + g * n[j]


@njit
def _glass_kernel(ior, mat, front, cos_s, wt, has_wt, sens, defended, defensive, u, u_lam, k, d, ns, ng, p, eps,
                  flat, refl, wr, rd, ro, parent, lam, w, e_out, t_dir, o_out, side_out):
    """split_at_glass's smooth-glass lines per ray: Fresnel per wavelength, the white reflect /
    refract choice, the reflected ray (``refl``, ``wr``, ``rd``, ``ro``) or ``draw``'s K children
    refracted at their wavelengths (``parent`` .. ``side_out``, compacted); returns their count."""
    b, n = mat.shape[0], ior.shape[1]
    fr, q, qf, pdf, cdf = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    two = np.float32(2.0)
    m = 0
    for i in range(b):
        mi = mat[i]
        c = abs(np.float64(cos_s[i]))
        for kk in range(n):
            nk = np.float64(ior[mi, kk])
            fr[kk] = _fresnel64(c, nk if front[i] else 1.0 / nk)
            q[kk] = (np.float64(wt[i, kk]) if has_wt else 1.0) * sens[kk]
            qf[kk] = q[kk] * fr[kk]
        qs = _pairwise(q, 0, n)
        p_refl = _pairwise(qf, 0, n) / qs if qs > 0 else 1.0
        refl[i] = u[i] < p_refl
        if refl[i]:  # white reflection, weight w F / P
            for kk in range(n):
                v = np.float32(fr[kk] / p_refl)
                wr[i, kk] = v * wt[i, kk] if has_wt else v
            s = (d[i, 0] * ns[i, 0] + d[i, 1] * ns[i, 1]) + d[i, 2] * ns[i, 2]
            for j in range(3):
                rd[i, j] = d[i, j] - two * s * ns[i, j]
                ro[i, j] = p[i, j] + eps[i] * ng[i, j]
            continue
        if not qs > 0:
            continue
        cnt = 0
        for kk in range(n):
            pdf[kk] = q[kk] / qs
            if (wt[i, kk] if has_wt else 1.0) > 0:
                cnt += 1
        if defended:  # _defended's uniform share over the support
            for kk in range(n):
                sup = 1.0 if (wt[i, kk] if has_wt else 1.0) > 0 else 0.0
                pdf[kk] = (1.0 - defensive) * pdf[kk] + defensive * sup / max(cnt, 1)
        acc = 0.0
        for kk in range(n):
            acc = pdf[kk] if kk == 0 else acc + pdf[kk]
            cdf[kk] = acc
        for j in range(k):  # sample_indices at the rotated numbers
            thr = np.fmod(np.float64(u_lam[i]) + j / k, 1.0) * cdf[n - 1]
            li = 0
            for kk in range(n):
                if cdf[kk] < thr:
                    li += 1
            li = min(li, n - 1)
            target = np.float64(wt[i, li]) if has_wt else 1.0
            wv = target / (k * pdf[li]) * (1.0 - fr[li]) / (1.0 - p_refl)
            if not wv > 0:  # cannot refract (total internal reflection): no child
                continue
            nk = np.float64(ior[mi, li])
            e = np.float32(1.0 / nk if front[i] else nk)
            _refract32(d[i], ns[i], e, t_dir[m])
            if not flat:
                dn = (t_dir[m, 0] * ng[i, 0] + t_dir[m, 1] * ng[i, 1]) + t_dir[m, 2] * ng[i, 2]
                if dn >= 0:  # refracted about ns onto the incident side: about ng instead
                    _refract32(d[i], ng[i], e, t_dir[m])
            dn = (t_dir[m, 0] * ng[i, 0] + t_dir[m, 1] * ng[i, 1]) + t_dir[m, 2] * ng[i, 2]
            sd = np.float32(1.0) if dn > 0 else np.float32(-1.0)
            for jj in range(3):
                o_out[m, jj] = p[i, jj] + (eps[i] * sd) * ng[i, jj]
            parent[m], lam[m], w[m], e_out[m], side_out[m] = i, li, wv, e, sd
            m += 1
    return m


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

"""The next-event stage's compiled kernels (core/integrators/eye/next_event.py's fused routines).

Method: next_event.py's direct light, Lambertian next events and caustic lookup (docs/physics.md
sections 4.2, 4.5: light sampling with Veach's power heuristic, the illumination map's
irradiance) per row in one pass each, reading the batch's arrays and adding to the film in place
without (B, n) temporaries; the routines that call them (``next_event._direct_fused``,
``_lambert_fused``, ``_caustic_fused``) keep the NumPy lines as the reference. The kernels do the
reference's float32 / float64 operations in its order (no fastmath), and add to the film as
TileOutput.accumulate does, so they give its bits (tests/integrators/eye/test_next_event_kernels.py
says where they do not: a sum over several lights, which the reference forms by BLAS).
"""

from __future__ import annotations

import numpy as np

from ...transport.elements import element_of
from ...transport.walker import Rays
from ...util.jit import njit

__all__ = ["ray_weights", "pixel_order", "caustic_kernel", "lambert_weigh", "lambert_add", "direct_weigh",
           "direct_add", "lobe_add", "flush_run", "NO_F32", "NO_F32_2", "NO_RGB", "NO_I64"]


# The film adds below are TileOutput.accumulate's, row by row: white rays summed per run of a
# pixel (rays in pixel order, stably sorted where they are not) and each run's sum added to the
# film once, mono rays added one by one in their order: the same float32 sums in the same order
# (np.add.reduceat's sum of a run is its first row plus NumPy's pairwise sum of the others:
# ``_pairwise``, ``flush_run``).

NO_F32 = np.zeros(0, np.float32)


NO_F32_2 = np.zeros((0, 0), np.float32)


def ray_weights(rays: Rays):
    """(mode, w (B, n), w (B,), basis row (n,)) of ``rays`` for the kernels: mode 0 unit weight,
    1 grey coefficients over a one-row basis (or mono weights), 2 spectral weights; None when the
    weights have another form (the NumPy lines run)."""
    w = rays.w
    if w is None:
        return (0, NO_F32_2, NO_F32, NO_F32) if rays.lam is None else None
    if w.dtype != np.float32:
        return None
    if rays.lam is not None:
        return 1, NO_F32_2, np.ascontiguousarray(w), NO_F32
    if rays.basis is not None:
        if rays.basis.shape[0] != 1 or rays.basis.dtype != np.float32:
            return None
        return 1, NO_F32_2, np.ascontiguousarray(w[:, 0]), np.ascontiguousarray(rays.basis[0])
    return 2, np.ascontiguousarray(w), NO_F32, NO_F32


def pixel_order(rays: Rays) -> np.ndarray:
    """The rows in the order TileOutput.accumulate sums them (pixel order, stable; mono: as given)."""
    pix = rays.pix
    if rays.lam is None and len(pix) > 1 and np.any(pix[1:] < pix[:-1]):
        return np.argsort(pix, kind="stable")
    return np.arange(len(pix))


@njit
def _weight_at(mode, w2, w1, basis, i, k):
    """The ray weight of row i at wavelength k (see ray_weights)."""
    if mode == 0:
        return np.float32(1.0)
    if mode == 1:
        return w1[i] * basis[k]
    return w2[i, k]


@njit
def _pw_block(buf, start, count, k):
    """NumPy's pairwise_sum of float32 buf[start:start + count, k] for count <= 128
    (numpy/_core/src/umath/loops_utils.h: sequential below 8 terms, else 8 partial sums)."""
    if count < 8:
        res = np.float32(0.0)
        for i in range(count):
            res += buf[start + i, k]
        return res
    r0, r1, r2, r3 = buf[start, k], buf[start + 1, k], buf[start + 2, k], buf[start + 3, k]
    r4, r5, r6, r7 = buf[start + 4, k], buf[start + 5, k], buf[start + 6, k], buf[start + 7, k]
    i = 8
    end = count - count % 8
    while i < end:
        r0 += buf[start + i, k]
        r1 += buf[start + i + 1, k]
        r2 += buf[start + i + 2, k]
        r3 += buf[start + i + 3, k]
        r4 += buf[start + i + 4, k]
        r5 += buf[start + i + 5, k]
        r6 += buf[start + i + 6, k]
        r7 += buf[start + i + 7, k]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < count:
        res += buf[start + i, k]
        i += 1
    return res


@njit
def _pairwise(buf, start, count, k):
    """NumPy's pairwise_sum of float32 buf[start:start + count, k]: blocks of up to 128 terms
    (_pw_block), above that the sum of the two halves (the first a multiple of 8 long), here
    with an explicit stack (numba's on-disk cache cannot hold a recursive function)."""
    if count <= 128:
        return _pw_block(buf, start, count, k)
    ss, cc, stage = np.empty(64, np.int64), np.empty(64, np.int64), np.empty(64, np.int64)
    left, right = np.empty(64, np.float32), np.empty(64, np.float32)
    ss[0], cc[0], stage[0] = start, count, 0
    sp = 1
    v = np.float32(0.0)
    while sp > 0:
        t = sp - 1
        c = cc[t]
        done = False
        if c <= 128:
            v = _pw_block(buf, ss[t], c, k)
            done = True
        elif stage[t] < 2:  # push the left half (stage 0), then the right half (stage 1)
            half = c // 2
            half -= half % 8
            ss[sp] = ss[t] if stage[t] == 0 else ss[t] + half
            cc[sp] = half if stage[t] == 0 else c - half
            stage[sp] = 0
            stage[t] += 1
            sp += 1
        else:
            v = left[t] + right[t]
            done = True
        if done:
            sp -= 1
            if sp > 0:
                if stage[sp - 1] == 1:
                    left[sp - 1] = v
                else:
                    right[sp - 1] = v
    return v


@njit
def flush_run(film, n, pix, buf, count):
    """film[pix] += the sum of the run's rows buf[:count] as np.add.reduceat forms it."""
    base = pix * n
    if count == 1:
        for k in range(n):
            film[base + k] += buf[0, k]
        return
    for k in range(n):
        film[base + k] += buf[0, k] + _pairwise(buf, 1, count - 1, k)


@njit
def _max_run(pix, order):
    """The longest run of one pixel in ``order`` (a bound on the run buffer's rows)."""
    best, run, cur = 0, 0, -1
    for t in range(len(order)):
        p = pix[order[t]]
        run = run + 1 if p == cur else 1
        cur = p
        if run > best:
            best = run
    return best


@njit
def caustic_kernel(film, n, pix, order, lam, mode, w2, w1, basis, lit_tri, k_tri, offset, element_area, flux,
                    prim, bu, bv, front, r1, r2, albedo, arow):
    """caustic_light per row (the rows of lit triangles, ``lit_tri``): the jittered element
    (element_of, numbers r1, r2 in the lit rows' order), its irradiance flux / area, times the
    base colour albedo[arow] * float32(1 / pi) and the ray weight, added to the film."""
    b = len(prim)
    rank = np.empty(b, np.int64)
    m = 0
    for i in range(b):
        rank[i] = m
        if lit_tri[prim[i]]:
            m += 1
    inv_pi = np.float32(1 / np.pi)
    mono = lam.shape[0] > 0
    buf = np.empty((max(_max_run(pix, order), 1), n), np.float32)  # the rows of one pixel's run
    cur = -1
    cnt = 0
    for t in range(b):
        i = order[t]
        if not lit_tri[prim[i]]:
            continue
        e, ok = element_of(k_tri, offset, prim[i], bu[i], bv[i], front[i], r1[rank[i]], r2[rank[i]], True)
        area = np.float32(element_area[prim[i]])
        a = arow[i]
        if mono:
            kk = lam[i]
            irr = flux[e, kk] / area if ok else np.float32(0.0)
            film[pix[i] * n + kk] += w1[i] * (irr * (albedo[a, kk] * inv_pi))
            continue
        if pix[i] != cur:
            if cnt > 0:
                flush_run(film, n, cur, buf, cnt)
            cur = pix[i]
            cnt = 0
        for kk in range(n):
            irr = flux[e, kk] / area if ok else np.float32(0.0)
            buf[cnt, kk] = _weight_at(mode, w2, w1, basis, i, kk) * (irr * (albedo[a, kk] * inv_pi))
        cnt += 1
    if cnt > 0:
        flush_run(film, n, cur, buf, cnt)


@njit
def lambert_weigh(wi, g, p_light, d, ns, ng, bump_v, p, eps, dist, pad, scale, live, o_out, t_out):
    """LambertLobe.weigh and visible's shadow-ray setup per row: scale (B,) = g cos / pi times
    the bump term (``bump_v``, empty: 1) and the power heuristic against cosine sampling; the rows
    with scale > 0 into ``live`` with their shadow rays' origins and lengths. Returns their count."""
    inv_pi = np.float32(1 / np.pi)
    two = np.float32(2.0)
    m = 0
    for i in range(len(g)):
        wo_up = d[i, 0] * ns[i, 0] + d[i, 1] * ns[i, 1] + d[i, 2] * ns[i, 2] < 0
        cs = wi[i, 0] * ns[i, 0] + wi[i, 1] * ns[i, 1] + wi[i, 2] * ns[i, 2]
        cg = wi[i, 0] * ng[i, 0] + wi[i, 1] * ng[i, 1] + wi[i, 2] * ng[i, 2]
        pb = np.float32(cs * inv_pi) if (wo_up and cs > 0 and cg > 0) else np.float32(0.0)
        s = g[i] * pb
        if bump_v.shape[0] > 0:
            s = s * bump_v[i]
        a2, b2 = p_light[i] * p_light[i], pb * pb
        w = a2 / (a2 + b2) if a2 + b2 > 0 else np.float32(1.0)
        if not np.isfinite(w):
            w = np.float32(1.0)
        s = s * w
        scale[i] = s
        if s > 0:
            live[m] = i
            e = eps[i]
            for k in range(3):
                o_out[m, k] = p[i, k] + e * ng[i, k]
            dd = dist[i]
            t_out[m] = np.inf if np.isinf(dd) else np.float32((dd - two * e) - pad[i])
            m += 1
    return m


@njit
def _uplift_shape(rgb, i):
    """Row i of spectral.spectrum's illuminant uplift (_uplift_kernel, as_light): (scale, shape
    r, g, b) in float64, the spectrum at wavelength k being _uplift_at(...)."""
    r, g, bl = np.float64(rgb[i, 0]), np.float64(rgb[i, 1]), np.float64(rgb[i, 2])
    r, g, bl = (0.0 if r < 0.0 else r), (0.0 if g < 0.0 else g), (0.0 if bl < 0.0 else bl)
    scale = r
    if g > scale or g != g:
        scale = g
    if (bl > scale or bl != bl) and scale == scale:
        scale = bl
    if scale > 0.0:
        r, g, bl = r / scale, g / scale, bl / scale
    else:
        r = g = bl = 0.0
    r = 0.0 if r < 0.0 else (1.0 if r > 1.0 else r)
    g = 0.0 if g < 0.0 else (1.0 if g > 1.0 else g)
    bl = 0.0 if bl < 0.0 else (1.0 if bl > 1.0 else bl)
    return scale, r, g, bl


@njit
def _uplift_at(shape, basis_t, k):
    """The uplifted spectrum of _uplift_shape's ``shape`` at wavelength k, as float32 (the
    light sample's spectrum, _uplift_kernel's float64 value cast as light_samples casts it)."""
    scale, r, g, bl = shape
    return np.float32(scale * (r * basis_t[0, k] + g * basis_t[1, k] + bl * basis_t[2, k]))


@njit
def lambert_add(film, n, pix, order, keep, lam, mode, w2, w1, basis, albedo, arow, acol_fixed, scale,
                 rgb, basis_t, table, srow):
    """LambertLobe.contribution and the film add for the rows ``keep``: the ray weight times
    albedo[arow] * scale times the light sample's spectrum (rgb rows uplifted when ``rgb`` has
    rows, else table[srow]), summed per pixel run as TileOutput.accumulate does."""
    mono = lam.shape[0] > 0
    uplift = rgb.shape[0] > 0
    buf = np.empty((max(_max_run(pix, order), 1), n), np.float32)  # the rows of one pixel's run
    cur = -1
    cnt = 0
    for t in range(len(order)):
        i = order[t]
        if not keep[i]:
            continue
        a, sc = arow[i], scale[i]
        shape = _uplift_shape(rgb, i) if uplift else (0.0, 0.0, 0.0, 0.0)
        if mono:
            kk = lam[i]
            sp = _uplift_at(shape, basis_t, kk) if uplift else table[srow[i], kk]
            film[pix[i] * n + kk] += ((w1[i] * albedo[a, 0 if acol_fixed else kk]) * sc) * sp
            continue
        if pix[i] != cur:
            if cnt > 0:
                flush_run(film, n, cur, buf, cnt)
            cur = pix[i]
            cnt = 0
        for kk in range(n):
            sp = _uplift_at(shape, basis_t, kk) if uplift else table[srow[i], kk]
            buf[cnt, kk] = _weight_at(mode, w2, w1, basis, i, kk) * ((albedo[a, kk] * sc) * sp)
        cnt += 1
    if cnt > 0:
        flush_run(film, n, cur, buf, cnt)


NO_RGB = np.zeros((0, 3), np.float32)


NO_I64 = np.zeros(0, np.int64)


@njit
def direct_weigh(li, wi, g, p_light, has_pdf, dist, ns, ng, flat, bump_v, p, eps, factors, o_out, d_out, t_out,
                  idx_out, m):
    """direct_light's factor of light ``li`` per row (g cos times the bump term and, ``has_pdf``,
    the power heuristic against cosine sampling) into factors[:, li], and the shadow rays of the
    rows with a factor > 0 appended at ``m``; returns the new count."""
    inv_pi = np.float32(1 / np.pi)
    two = np.float32(2.0)
    nl = factors.shape[1]
    for i in range(len(g)):
        cs = wi[i, 0] * ns[i, 0] + wi[i, 1] * ns[i, 1] + wi[i, 2] * ns[i, 2]
        ok = cs > 0 and (flat or wi[i, 0] * ng[i, 0] + wi[i, 1] * ng[i, 1] + wi[i, 2] * ng[i, 2] > 0)
        f = np.float32(0.0)
        if ok:
            f = g[i] * cs
            if bump_v.shape[0] > 0:
                f = f * bump_v[i]
        if has_pdf:
            pb = (cs if cs > 0 else np.float32(0.0)) * inv_pi
            a2, b2 = p_light[i] * p_light[i], pb * pb
            w = a2 / (a2 + b2) if a2 + b2 > 0 else np.float32(1.0)
            if not np.isfinite(w):
                w = np.float32(1.0)
            f = f * w
        if f > 0:
            factors[i, li] = f
            e = eps[i]
            for k in range(3):
                o_out[m, k] = p[i, k] + e * ng[i, k]
                d_out[m, k] = wi[i, k]
            dd = dist[i]
            t_out[m] = np.inf if np.isinf(dd) else dd - two * e
            idx_out[m] = i * nl + li
            m += 1
    return m


@njit
def direct_add(film, n, pix, order, lam, mode, w2, w1, basis, albedo, arow, acol_fixed, factors, spectrum):
    """direct_light's contribution and film add per row: the ray weight times albedo[arow] *
    float32(1 / pi) times the irradiance sum over lights of factors * spectrum, summed per pixel
    run as TileOutput.accumulate does."""
    inv_pi = np.float32(1 / np.pi)
    nl = factors.shape[1]
    mono = lam.shape[0] > 0
    buf = np.empty((max(_max_run(pix, order), 1), n), np.float32)  # the rows of one pixel's run
    cur = -1
    cnt = 0
    for t in range(len(order)):
        i = order[t]
        a = arow[i]
        if mono:
            kk = lam[i]
            irr = factors[i, 0] * spectrum[0, kk]
            for li in range(1, nl):
                irr += factors[i, li] * spectrum[li, kk]
            film[pix[i] * n + kk] += w1[i] * ((albedo[a, 0 if acol_fixed else kk] * inv_pi) * irr)
            continue
        if pix[i] != cur:
            if cnt > 0:
                flush_run(film, n, cur, buf, cnt)
            cur = pix[i]
            cnt = 0
        for kk in range(n):
            irr = factors[i, 0] * spectrum[0, kk]
            for li in range(1, nl):
                irr += factors[i, li] * spectrum[li, kk]
            buf[cnt, kk] = _weight_at(mode, w2, w1, basis, i, kk) * ((albedo[a, kk] * inv_pi) * irr)
        cnt += 1
    if cnt > 0:
        flush_run(film, n, cur, buf, cnt)


@njit
def lobe_add(film, n, pix, order, keep, lam, mode, w2, w1, basis, value, scale, table, srow):
    """next_events' contribution of a lobe (MicrofacetLobe.contribution) and the film add for the
    rows ``keep``: the ray weight times value (f cos, (B, n) or (B, 1)) * scale times the light
    sample's spectrum table[srow], summed per pixel run as TileOutput.accumulate does."""
    mono = lam.shape[0] > 0
    wide = value.shape[1] > 1
    buf = np.empty((max(_max_run(pix, order), 1), n), np.float32)  # the rows of one pixel's run
    cur = -1
    cnt = 0
    for t in range(len(order)):
        i = order[t]
        if not keep[i]:
            continue
        sc, s = scale[i], srow[i]
        if mono:
            kk = lam[i]
            film[pix[i] * n + kk] += (w1[i] * (value[i, 0] * sc)) * table[s, kk]
            continue
        if pix[i] != cur:
            if cnt > 0:
                flush_run(film, n, cur, buf, cnt)
            cur = pix[i]
            cnt = 0
        for kk in range(n):
            buf[cnt, kk] = _weight_at(mode, w2, w1, basis, i, kk) * ((value[i, kk if wide else 0] * sc) * table[s, kk])
        cnt += 1
    if cnt > 0:
        flush_run(film, n, cur, buf, cnt)

"""Both Fresnel branches at a camera ray's first glass hit, instead of a random choice.

At a smooth dielectric the eye pass picks reflection with probability F (the Fresnel
reflectance) and refraction otherwise, weight unchanged (core/transport/walker.py): an unbiased
one-sample estimate of F L_r + (1 - F) L_t whose choice adds the variance F (1 - F) (L_r - L_t)^2
to every sample. Splitting (Arvo & Kirk 1990, "Particle transport and image synthesis",
section 4; pbrt-v3's Whitted integrator and Cycles' branched path tracing do the same at
chosen vertices) traces both: the reflected ray with weight F and the refracted one with weight
1 - F, so that term is gone at the cost of one more ray per camera sample on the glass. Only at
the first specular vertex from the camera (depth 0): deeper vertices would double the rays at
every bounce, and there the choice's share of the variance is small (docs/physics.md section
4.12, benchmarks/sphere_noise.py). Under total internal reflection (F = 1) only the reflected
child is kept. Russian roulette (eye_pass ``survives``) divides the split weight out of the
throughput it judges by (the path's ``PathState.split``), so a child of weight F is kept as often as
its unsplit path would be (any survival probability keeps the estimate unbiased; this one adds
no roulette noise where the unsplit path had none). The setting ``fresnel_split`` (render/plan.py's
``fresnel_split``, off where gratings layer their bases) switches it off, as
benchmarks/caustic_sphere.py does to measure the difference.
"""

from __future__ import annotations

import numpy as np

from ...spectral.optics import fresnel_dielectric
from ...transport.walker import Hit, Rays

__all__ = ["split_first_dielectric"]


def split_first_dielectric(walker, rays: Rays, hit: Hit, rng, u, dielectric):
    """``dielectric(rays, hit, rng, u) -> (rays, transmitted)`` (the walker's Fresnel-sampled
    bounce: reflect where u < F; u None draws from ``rng``) with camera rays (depth 0) split into
    both branches, weights F and 1 - F (u = 0 takes the reflection, u = 1 the refraction); the
    other rays as ``dielectric`` does them with their ``u``. Returns (rays going on, transmitted (B',) bool); rows are
    not in the input's order."""
    first = rays.depth == 0
    if not first.any():
        return dielectric(rays, hit, rng, u)
    idx = np.flatnonzero(first)
    rf, hf = rays.take(idx), hit.take(idx)
    ior = walker.prepared.materials.ior
    n = np.take(ior[:, 0], hf.mat) if rf.lam is None else ior[hf.mat, rf.lam]
    eta = np.where(hf.front, n, 1.0 / n).astype(np.float32)  # n_t / n_i
    ns = walker.specular_normal(rf, hf)
    cos = hf.cos_i if ns is hf.ng else -np.einsum("ij,ij->i", rf.d, ns)
    fr = np.asarray(fresnel_dielectric(np.abs(cos), eta)[0], np.float32)
    fr = walker._glass_fresnel(rf, hf, np.abs(cos), n, fr)  # a thin film's (docs/physics.md section 2.8)
    # reflected children where F > 0, refracted ones where F < 1 (not under total internal reflection)
    refl, refr = np.flatnonzero(fr > 0), np.flatnonzero(fr < 1)
    pick = np.concatenate([refl, refr])
    u_split = np.concatenate([np.zeros(len(refl)), np.ones(len(refr))])
    factor = np.concatenate([fr[refl], 1 - fr[refr]]).astype(np.float32)
    out, transmitted = dielectric(rf.take(pick), hf.take(pick), rng, u_split)
    k = walker.n
    if out.w is None:
        w = np.repeat(factor[:, None], k, axis=1)
    elif out.w.ndim == 2:
        w = out.w * factor[:, None]
    else:
        w = out.w * factor
    out.w = w.astype(np.float32, copy=False)
    if out.state is not None:  # Russian roulette judges the unsplit path
        out.state.split = out.state.split * np.maximum(factor, np.float32(1e-30))
    if idx.size == len(rays):
        return out, transmitted
    rest = np.flatnonzero(~first)
    o2, t2 = dielectric(rays.take(rest), hit.take(rest), rng, None if u is None else u[rest])
    if o2.w is None:  # join unit weights as ones
        o2.w = np.ones((len(o2), k), np.float32) if out.lam is None else np.ones(len(o2), np.float32)
    return Rays.concat(out, o2), np.concatenate([transmitted, t2])

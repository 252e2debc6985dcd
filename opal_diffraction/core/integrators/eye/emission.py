"""The emission stage of the eye pass: emitted light a path finds by itself, weighted by MIS.

What a BSDF-sampled (or camera) segment meets (docs/physics.md sections 4.5, 7.9): sized lights
it passes (``lights_passed``), soft suns and the world where it leaves the scene
(``escaped``), and emissive surfaces it hits (``surface_emission``), each weighted against the
next-event stage's sampling of the same emitter by the power heuristic (Veach 1997, section 9.2;
core/integrators/eye/next_event.py), which the path's last BSDF pdf (``PathState.pdf``) feeds.
Lights are invisible to camera rays and transparent to paths, as Cycles' default ray visibility
has them; a caustic path the light pass counted is left out (``not_covered``).

Where the kernels run (core/util/jit.py) the world map seen by escaping rays takes three compiled
passes instead of a chain of NumPy calls: the map's radiance and density per direction
(``EnvironmentMap.lookup``), each ray's contribution (``_world_contrib_kernel``: the uplift of
``illuminant_from_rgb``'s kernel, the power heuristic, the ray's weight, in the chain's
operations and precisions) and the film deposit of all vertex counts at once
(``TileOutput.add_by_vertices``): the same bits as the chain on the kernels. The sized lights a
segment passes and their pdfs come from one call (core/lights/sources.py's ``lights_met``: two
compiled passes there), and only the rays that meet one are gathered.
"""

from __future__ import annotations

import numpy as np

from ...lights.sources import light_pdf, lights_met, sun_radiance
from ...materials.surface import surface_emission
from ...transport.path_state import Caustic
from ...transport.walker import Hit, Rays
from ...util.jit import kernels_enabled, njit
from .factored_film import add_scaled_spectra
from .next_event import power_heuristic

__all__ = ["not_covered", "lights_passed", "escaped", "world_seen", "surface_emission_unit", "surface_emitted"]


def not_covered(c, rays: Rays) -> np.ndarray:
    """Rays whose emitter hit is not a caustic path the light pass counted (section 4.5)."""
    if not c.caustics_cover_lights:
        return np.ones(len(rays), bool)
    return rays.state.caustic != Caustic.PATH


def lights_passed(c, out, rays: Rays, t: np.ndarray) -> None:
    """Sized lights a segment passes before it hits anything (at distance ``t`` (B,)): their
    radiance, weighted against next-event estimation by the power heuristic."""
    if not c.hittable.any():
        return
    seen = not_covered(c, rays) & (rays.depth > 0)
    if not seen.any():
        return
    lights = c.prepared.lights
    # the lights met and their pdfs in one pass (lights_met), only the rays that meet one taken
    rows, idx, scale, p_light = lights_met(lights, rays.o, rays.d, t, seen)
    if len(rows) == 0:
        return
    r = rays.take(rows)
    scale = scale * power_heuristic(r.state.pdf, p_light)
    spectrum = lights.spectrum
    radiance = scale[:, None] * spectrum[idx] if r.lam is None else scale * spectrum[idx, r.lam]
    out.add_by_vertices(r, r.weighted(radiance))


def escaped(c, out, rays: Rays, escapes: list | None) -> None:
    """Rays that left the scene: the soft suns they see (MIS-weighted) and the world behind
    them; ``escapes``: a list to record the paths that met only mirrors and glass (trace_escapes),
    or None."""
    if len(c.soft_suns):
        lights = c.prepared.lights
        seen = not_covered(c, rays) & (rays.depth > 0)
        if seen.any():
            r = rays.take(seen)
            p_light = sum(light_pdf(lights, int(li), r.o, r.d) for li in c.soft_suns)
            rad = sun_radiance(lights, r.d) * power_heuristic(r.state.pdf, p_light)[:, None]
            out.add_by_vertices(r, r.weighted(rad) if r.lam is None else r.w * rad[np.arange(len(r)), r.lam])
        # camera rays see the discs of suns marked visible to them (a Sky Texture's sun, a lamp
        # with Visibility > Camera), with no light sample to share with: weight 1
        if lights.camera_visible[c.soft_suns].any():
            first = rays.depth == 0
            if first.any():
                r = rays.take(first)
                rad = sun_radiance(lights, r.d, camera=True)
                out.add_by_vertices(r, r.weighted(rad) if r.lam is None else r.w * rad[np.arange(len(r)), r.lam])
    st = rays.state
    if escapes is not None:
        first = st.nd == 0  # paths that met only mirrors and glass
        r = rays.take(first)
        escapes.append({"origin": r.o, "direction": r.d, "weight": r.dense_w(c.n),
                        "lam": r.lam, "depth": r.depth, "ray": r.pix})
    # the world through glass after a diffuse vertex is a caustic path the light pass
    # counted (it emits from the world too)
    keep = not_covered(c, rays)
    if not keep.all():
        rays = rays.take(keep)
        st = rays.state
    if kernels_enabled() and c.prepared.environment is not None and len(rays):
        contrib = _world_map_contrib(c, rays)
        if contrib is not None:  # every vertex count in one deposit (the sums one world_seen per count forms)
            out.add_by_vertices(rays, contrib)
            return
    for nd in np.unique(st.nd):
        world_seen(c, out, rays.take(st.nd == nd), out.light_film(min(int(nd), 2)))


def world_seen(c, out, rays: Rays, film):
    """The world along escaping rays into ``film``: the map (weighted against its next events)
    or the uniform background spectrum."""
    prepared = c.prepared
    env = prepared.environment
    if env is not None:  # the world map seen along the escaping rays (docs/physics.md section 7.9)
        if len(rays) == 0:
            return
        contrib = _world_map_contrib(c, rays) if kernels_enabled() else None
        if contrib is not None:
            out.accumulate(rays, contrib, film)
            return
        spectra = prepared.conv.illuminant_from_rgb(env.radiance_rgb(rays.d)).astype(np.float32)
        # a BSDF sample, weighted against the map's next-event estimation (power heuristic)
        spectra *= power_heuristic(rays.state.pdf, env.pdf(rays.d).astype(np.float32))[:, None]
        contrib = rays.weighted(spectra) if rays.lam is None else rays.w * spectra[np.arange(len(rays)), rays.lam]
        out.accumulate(rays, contrib, film)
        return
    bg = prepared.world_spectrum
    if not bg.any() or len(rays) == 0:
        return
    if c.greys.add_constant(film, rays, bg, out.n_pixels):  # grey weights: sums per pixel
        return
    if rays.lam is None and rays.w is None:  # unit weights: count rays per pixel
        counts = np.bincount(rays.pix, minlength=out.n_pixels).astype(np.float32)
        film[:] += (counts[:, None] * bg[None, :]).ravel()
        return
    contrib = rays.weighted(np.broadcast_to(bg, (len(rays), c.n)) if rays.lam is None else bg[rays.lam])
    out.accumulate(rays, contrib, film)


def _world_map_contrib(c, rays: Rays) -> np.ndarray | None:
    """world_seen's contributions of the map along ``rays`` (B, n) (white) or (B,) (mono)
    float32, by EnvironmentMap.lookup and _world_contrib_kernel; None (the NumPy chain then) for
    weights that are not float32."""
    prepared = c.prepared
    b, basis_t = len(rays), prepared.conv.emission_basis
    n, mono = basis_t.shape[1], rays.lam is not None
    if rays.w is None:
        if mono:
            return None
        w = _EMPTY_W
    else:
        w = rays.w.reshape(b, 1) if mono else rays.dense_w(n)
        if w.dtype != np.float32 or w.shape != ((b, 1) if mono else (b, n)):
            return None
    rgb, p_env = prepared.environment.lookup(rays.d)
    contrib = np.empty((b, 1) if mono else (b, n), np.float32)
    _world_contrib_kernel(np.ascontiguousarray(rgb, np.float32), p_env, np.asarray(rays.state.pdf, np.float32),
                          basis_t, w, rays.lam if mono else _NO_LAM, contrib)
    return contrib[:, 0] if mono else contrib


_EMPTY_W = np.ones((0, 0), np.float32)
_NO_LAM = np.zeros(0, np.int64)


@njit
def _world_contrib_kernel(rgb, p_env, p_bsdf, basis_t, w, lam, out):
    """Per ray: the map's radiance ``rgb`` (B, 3) uplifted to a spectrum as
    SpectralConverter.illuminant_from_rgb's kernel does (the maximum times the [0, 1] shape's
    basis combination, float64), rounded to float32, times power_heuristic(p_bsdf,
    float32(p_env)) and the ray's weight ``w`` ((B, n), (B, 1) for mono rays, empty: unit
    weights): out (B, n), or (B, 1) at the mono rays' wavelengths ``lam``."""
    mono = lam.shape[0] > 0
    weighted = w.shape[0] > 0
    one = np.float32(1.0)
    for b in range(rgb.shape[0]):
        r, g, bl = np.float64(rgb[b, 0]), np.float64(rgb[b, 1]), np.float64(rgb[b, 2])
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
        # the power heuristic (next_event.power_heuristic) in float32
        pa, pb = p_bsdf[b], np.float32(p_env[b])
        a2, b2 = pa * pa, pb * pb
        mis = a2 / (a2 + b2) if a2 + b2 > 0 else one
        if not pa > 0:
            mis = one
        if not np.isfinite(mis):
            mis = one
        if mono:
            k = lam[b]
            s = np.float32(scale * (r * basis_t[0, k] + g * basis_t[1, k] + bl * basis_t[2, k])) * mis
            out[b, 0] = w[b, 0] * s
            continue
        for k in range(basis_t.shape[1]):
            s = np.float32(scale * (r * basis_t[0, k] + g * basis_t[1, k] + bl * basis_t[2, k])) * mis
            out[b, k] = w[b, k] * s if weighted else s


def surface_emission_unit(c, out, rays: Rays, hit: Hit, emits: np.ndarray) -> bool:
    """``surface_emitted`` for unit-weight white rays (camera rays, through clear glass and
    mirrors) at untextured emitters with no MIS partner: the emission spectra added per pixel and
    material (core/integrators/eye/factored_film.py), no (B, n) spectrum per ray. False: not
    applicable, nothing added (the general path does it)."""
    prepared = c.prepared
    if rays.lam is not None or rays.w is not None or prepared.textures.uses("emission"):
        return False
    st = rays.state
    sel = emits & not_covered(c, rays)
    if c.mesh_lights is not None and (st.pdf[sel] > 0).any():
        return False  # weighted against the mesh lights' next events: the general path
    idx = np.flatnonzero(sel)
    nd = np.minimum(st.nd[idx], 2)
    groups = [idx] if len(nd) == 0 or (nd == nd[0]).all() else [idx[nd == k] for k in np.unique(nd)]
    table = prepared.materials.emission
    for j in groups:
        if len(j) and not add_scaled_spectra(out.light_film(min(int(st.nd[j[0]]), 2)), out.n_pixels,
                                             rays.pix[j], hit.mat[j], 1.0, table):
            surface_emitted(c, out, rays.take(j), hit.take(j))
    return True


def surface_emitted(c, out, rays: Rays, hit: Hit):
    """Emission of the surfaces hit (Cycles' units: the material's emission is radiance, seen
    from both sides), weighted against the mesh lights' next-event estimation by the power
    heuristic where a BSDF sample found it; a caustic path the light pass counted is left out."""
    keep = not_covered(c, rays)
    if not keep.all():
        rays, hit = rays.take(keep), hit.take(keep)
    if len(rays) == 0:
        return
    e = surface_emission(c.prepared, hit, rays.lam)
    pdf = rays.state.pdf
    if c.mesh_lights is not None and (pdf > 0).any():
        wgt = power_heuristic(pdf, c.mesh_lights.pdf(hit.prim, rays.o, hit.p).astype(np.float32))
        e = e * (wgt[:, None] if rays.lam is None else wgt)
    out.add_by_vertices(rays, rays.weighted(e) if rays.lam is None else rays.w * e)

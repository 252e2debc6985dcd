"""Caustic light after one more diffuse bounce, carried by the light paths to the camera.

The path E -> Y -> (specular)+ -> X -> (specular)+ -> L: a camera sees a plain diffuse floor Y,
whose diffuse bounce finds the glass and, through it, a caustic on the floor X. The eye pass
used to read it from the caustic map at X (docs/physics.md section 4.5): a cosine-sampled bounce
from Y must pass the glass *and* land in the caustic's small bright spot, a rare sample of a
large value (a peak of about 28 on the caustic-sphere benchmark): the isolated bright pixels on
the lit floor and in the shadow. Light tracing samples the same path from the other end, as
Mitsuba 3's ``ptracer`` does (Veach 1997, section 10.2): the light path that landed at X after
the glass (a landing the light pass deposits and splats, core/integrators/light/camera_splat.py) takes one
cosine-sampled Lambertian bounce (weight = the albedo rho(X): pbrt-v4 section 13.2's throughput
f cos / pdf), follows mirrors and glass, and where it lands on a diffuse surface Y after one or
more specular bounces it is joined to the camera by core/integrators/light/camera_splat.py's t = 1 connection
(docs/physics.md section 4.11).

The path-space split (each path counted once): the light side takes the paths whose eye end is
``E -> Y (plain diffuse, seen directly) -> bounce -> specular+ -> X`` with X a flat plain
diffuse hit (``receives``); the eye pass leaves the map out exactly there (``covered``: one
diffuse vertex before X, that vertex seen directly on a splat material, specular bounces since,
X receives) and keeps it everywhere else (more diffuse bounces, rough surfaces between, X rough
or bent by shading normals or a normal map). "Flat": the interpolated normal equals the
geometric one (to 1e-5), so the bounce at X needs no adjoint shading-normal correction (Veach
1997, section 5.3). The continuation is off in scenes with gratings or opal lobes (their
light-pass scattering is not followed here), with rough or layered materials (a singular layer
is a specular bounce to the eye pass and an end to a light path) and wherever the camera splat
is off; render/plan.py's ``splat_bounce`` decides it once per render (``applies``, the setting
``splat_bounce``), and both passes read the plan.
"""

from __future__ import annotations

import numpy as np

from ...materials.bsdf import cosine_hemisphere
from ...materials.spectra import DIFFUSE
from ...materials.surface import surface_reflectance
from ...transport.path_state import Caustic
from ...transport.walker import Hit, Rays, SpecularWalker

__all__ = ["applies", "receivers", "receives", "covered", "BounceLog", "trace_bounces"]

FLAT_TOLERANCE = 1e-5  # 1 - |ns . ng| below this: the hit's shading normal is its geometric one


def applies(prepared) -> bool:
    """Whether the scene lets the light pass continue its landings by a diffuse bounce (and so
    the eye pass leave those paths out), given the camera splat is on (the plan's
    ``camera_splat``): nothing it cannot follow scatters light paths (gratings, opal lobes, rough
    or layered surfaces) and some material receives (``receivers``)."""
    if prepared.gratings.any or getattr(prepared.gratings, "bragg", None) is not None and np.any(prepared.gratings.bragg):
        return False
    if prepared.microfacet is not None and np.any(prepared.microfacet):
        return False  # rough and layered surfaces: a singular layer would be specular to the eye, an end here
    return bool(receivers(prepared).any())


def receivers(prepared) -> np.ndarray:
    """(M,) bool: materials a continuation starts from (X) and lands on (Y): the splat's plain
    Lambertian materials (camera_splat.direct_materials) without a normal map."""
    from .camera_splat import direct_materials

    ok = direct_materials(prepared).copy()
    tx = prepared.textures
    if tx.uses("normal"):
        ok &= np.asarray(tx.normal) < 0
    return ok


def receives(mask: np.ndarray, hit: Hit) -> np.ndarray:
    """(B,) bool: hits on a ``receivers`` material whose shading normal is the geometric one."""
    cos = np.abs(np.einsum("ij,ij->i", hit.ns, hit.ng))
    return mask[hit.mat] & (cos > 1 - FLAT_TOLERANCE)


def covered(mask: np.ndarray, rays: Rays, hit: Hit) -> np.ndarray:
    """(B,) bool: eye-path diffuse vertices X whose caustic-map light the continuation carries:
    one diffuse vertex before (``PathState.nd`` = 1), that vertex seen straight from the camera on a
    receiving material (``seen``, set by ``mark_bounce``), specular bounces since (``caustic`` =
    Caustic.PATH), and X receiving (``receives``)."""
    st = rays.state
    return (st.nd == 1) & st.seen & (st.caustic == Caustic.PATH) & receives(mask, hit)


def mark_bounce(mask: np.ndarray | None, rays: Rays, hit: Hit) -> np.ndarray:
    """The ``seen`` state of eye paths bouncing off diffuse hits: the hit was seen straight from
    the camera (depth 0) and receives (``receives``)."""
    if mask is None:
        return np.zeros(len(rays), bool)
    return (rays.depth == 0) & receives(mask, hit)


class BounceLog:
    """The landings of one light batch (or SPLIT piece) to continue (``add`` from the light
    pass's on_hit), traced after its walk by ``trace_bounces`` with a random stream of their own
    (walker.trace_batch), so the walk's random numbers, its map and its direct splats are
    those of a light pass without them."""

    def __init__(self, prepared, mask: np.ndarray | None = None):
        self.mask = receivers(prepared) if mask is None else mask  # ``receivers``, if the caller has it
        self.landings: list[tuple[Rays, Hit]] = []

    def add(self, prepared, rays: Rays, hit: Hit, rng=None, rows=None) -> None:
        """Keep the landings (``rays`` at ``hit``, diffuse hits after a specular bounce; ``rows``:
        their indices into them, None: all) on receiving hits."""
        if rows is None:
            sel = receives(self.mask, hit)
            if sel.any():
                self.landings.append((rays.take(sel), hit.take(sel)))
            return
        at = rows[self.mask[hit.mat.take(rows)]]  # receives(), on the receiving materials' rows only
        if len(at):
            at = at[receives(self.mask, _Normals(hit.ns.take(at, axis=0), hit.ng.take(at, axis=0),
                                                 hit.mat.take(at)))]
        if len(at):
            self.landings.append((rays.take(at), hit.take(at)))

    def rays(self, prepared, rng: np.random.Generator) -> tuple[list[Rays], list[Rays]]:
        """(white, mono) continued rays: a cosine-sampled direction about the normal on the side
        the light arrived from, weight times rho(X), depth 0 (a later landing after glass has
        depth >= 1)."""
        white, mono = [], []
        for r, h in self.landings:
            rho = surface_reflectance(prepared, h, r.lam)
            wi, _ = cosine_hemisphere(h.ng, rng)  # ng faces the side the light came from; ns = ng here
            o = (h.p + h.eps[:, None] * h.ng).astype(np.float32)
            zero = np.zeros(len(r), np.int32)
            if r.lam is None:
                w = (r.dense_w(prepared.grid.n) * rho).astype(np.float32)
                white.append(Rays(o, wi, r.pix, w, None, zero, r.u_lam))
            else:
                mono.append(Rays(o, wi, r.pix, (r.w * rho).astype(np.float32), r.lam, zero, r.u_lam))
        return white, mono


class _Normals:
    """The fields of hits ``receives`` reads."""

    def __init__(self, ns, ng, mat):
        self.ns, self.ng, self.mat = ns, ng, mat


class _Continuation(SpecularWalker):
    """The continued light paths: through mirrors and glass, splatted where they land on a
    diffuse surface after a specular bounce (camera_splat.SplatBatch.connect), ended there."""

    def __init__(self, prepared, rng, batch):
        super().__init__(prepared, rng)
        self.batch = batch

    def on_hit(self, rays: Rays, hit: Hit, kind: np.ndarray, rng) -> None:
        rows = np.flatnonzero((kind == DIFFUSE) & (rays.depth >= 1))
        if len(rows):
            self.batch.connect(self.prepared, rays, hit, self.n, rows)


def trace_bounces(prepared, log: BounceLog, batch, rng: np.random.Generator) -> int:
    """Trace a batch's continuations (``log``) and splat their landings into ``batch``
    (camera_splat.SplatBatch); returns the rays cast (shadow rays are the batch's)."""
    if not log.landings:
        return 0
    ws, ms = log.rays(prepared, rng)
    cat = lambda rs: rs[0] if len(rs) == 1 else _concat(rs)  # noqa: E731
    white = cat(ws) if ws else None
    mono = cat(ms) if ms else SpecularWalker.empty_mono()
    tr = _Continuation(prepared, rng, batch)
    if white is None:
        white = SpecularWalker.empty_mono().take(np.zeros(0, bool))
        white = Rays(white.o, white.d, white.pix, np.zeros((0, prepared.grid.n), np.float32), None, white.depth,
                     white.u_lam)
    tr.walk(white, mono)
    return tr.rays_cast


def _concat(rs):
    out = rs[0]
    for r in rs[1:]:
        out = Rays.concat(out, r)
    return out

"""The camera splat's light-path vertices, kept, and splatted again into another camera.

The camera splat (core/integrators/light/camera_splat.py, docs/physics.md section 4.9) joins each
light-path landing on a plain diffuse surface to the camera: a shadow ray, the Lambertian BRDF
toward the eye and the pinhole's importance W_e, the filter footprint. Only that last step
depends on the camera; where the landings are, what flux they carry and what surface they lie on
do not (the light paths start at the lights and are aimed at the casters, and the splat bounce's
continuations (section 4.11) draw their directions from a stream of their own). So a light pass
asked to keep them (``run_light_pass(..., keep_vertices=cap)``) keeps, for every landing the
splat connects (direct and after the splat bounce), what ``CameraConnection.connect`` reads of it:
its point, geometric normal and self-intersection offset, its material (and triangle and
barycentrics where a colour texture is looked up), its weights (the flux per wavelength sample,
a mono path's one wavelength, or coefficients over a white population's shared spectra) -
``SplatVertices``. For another view of the same prepared scene (the engine's persistent data
between animation frames, blender/persistent.py) ``resplat`` connects the kept vertices to the
new camera (the same shadow rays through the ray caster, the BRDF toward the new eye, the new
camera's importance and filter) instead of tracing the light paths again: light tracing's t = 1
strategy (Veach 1997, section 10.2; Mitsuba 3's ``ptracer``) evaluated for a second camera on
the same light subpaths.

The vertices are kept in the order the light pass connected them: per lane, per batch, per
SPLIT piece (``walker.trace_batch``), each ``SplatBatch.connect`` call one chunk. A re-splat
connects the chunks in that order, sums each piece per pixel and adds the pieces to the lane's
film, and adds the lanes in lane order, as the light pass does: the film is the one a light pass
run for the new camera makes, bit for bit (the same landings, the same arithmetic, the same
order; tests/integrators/light/test_splat_vertices.py).

Memory: 44 bytes per mono landing (a path split by a dispersive glass), 32 + 4 k per white
one (k spectral samples or basis coefficients); ``VertexKeeper`` stops keeping past its cap
(bytes) and says so (``SplatVertexStore.over_cap``): a later view then runs the light pass again.
Measured on the prism example: docs/benchmarks.md, "Persistent data".
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from types import MappingProxyType

import numpy as np

from ...util.blas_threads import one_blas_thread
from ...transport.walker import dense_weights
from .camera_splat import CameraConnection, SplatBatch

__all__ = ["SplatVertices", "RecordingSplatBatch", "VertexKeeper", "SplatVertexStore", "resplat", "resplat_note"]


@dataclass(frozen=True)
class SplatVertices:
    """Landings the camera splat connects (one ``connect`` call's, on the splat's materials), with
    what the connection reads of them; passed to ``CameraConnection.connect`` as both its rays and
    its hits. ``prim``, ``bu``, ``bv`` are None where no colour texture is looked up
    (surface.surface_reflectance reads them only then)."""

    p: np.ndarray              # (K, 3) float32 points
    ng: np.ndarray             # (K, 3) float32 geometric normals, on the side the light arrived from
    eps: np.ndarray            # (K,) float32 self-intersection offsets
    mat: np.ndarray            # (K,) material indices
    prim: np.ndarray | None    # (K,) triangles, or None
    bu: np.ndarray | None      # (K,) barycentrics, or None
    bv: np.ndarray | None
    w: np.ndarray | None       # (K,) mono weights, (K, n) spectra or (K, k) coefficients over ``basis``; None: 1
    lam: np.ndarray | None     # (K,) wavelength index of mono paths; None: white
    basis: np.ndarray | None   # (k, n) float32 spectra shared by a white population, or None

    @classmethod
    def of(cls, materials: np.ndarray, rays, hit, rows: np.ndarray | None, textured: bool) -> "SplatVertices | None":
        """The landings ``rows`` of ``rays`` at ``hit`` (None: all) on ``materials`` (M,) bool (the
        connection's ``materials``), copied; None when none is on them."""
        at = (np.flatnonzero(materials[hit.mat]) if rows is None
              else np.asarray(rows)[materials[hit.mat.take(rows)]])
        if not len(at):
            return None

        def take(a):
            return None if a is None else a.take(at, axis=0)

        return cls(take(hit.p), take(hit.ng), take(hit.eps), take(hit.mat),
                   take(hit.prim) if textured else None, take(hit.bu) if textured else None,
                   take(hit.bv) if textured else None, take(rays.w), take(rays.lam), rays.basis)

    def __len__(self) -> int:
        return len(self.mat)

    def take(self, rows) -> "SplatVertices":
        """The vertices at ``rows`` (indices, or a (K,) bool mask)."""
        idx = np.flatnonzero(rows) if np.asarray(rows).dtype == bool else np.asarray(rows)

        def take(a):
            return None if a is None else a.take(idx, axis=0)

        return SplatVertices(take(self.p), take(self.ng), take(self.eps), take(self.mat), take(self.prim),
                             take(self.bu), take(self.bv), take(self.w), take(self.lam), self.basis)

    def dense_w(self, n: int) -> np.ndarray:
        """transport.Rays.dense_w of the landings: (K, n) spectral weights (white paths)."""
        return dense_weights(self.w, self.basis, len(self), n)

    @property
    def nbytes(self) -> int:
        """The bytes of its arrays (a shared basis not counted: ``SplatVertexStore`` counts it once)."""
        return sum(a.nbytes for a in (self.p, self.ng, self.eps, self.mat, self.prim, self.bu, self.bv, self.w,
                                      self.lam) if a is not None)


class RecordingSplatBatch(SplatBatch):
    """A ``SplatBatch`` that keeps the vertices it connects (``kept``: one ``SplatVertices`` per
    call) and connects them from the kept copy, so its splats are those a re-splat of the copy
    makes for the same camera."""

    def __init__(self, connection: CameraConnection, textured: bool):
        super().__init__(connection)
        self.textured = textured
        self.kept: list[SplatVertices] = []

    def connect(self, prepared, rays, hit, n: int, rows=None) -> None:
        v = SplatVertices.of(self.connection.materials, rays, hit, rows, self.textured)
        if v is None:
            return
        self.kept.append(v)
        super().connect(prepared, v, v, n)


@dataclass(frozen=True)
class SplatVertexStore:
    """A light pass's kept splat vertices: ``lanes[k]`` the pieces of lane k in its order, each
    piece a tuple of ``SplatVertices`` chunks; None when ``over_cap`` (then ``nbytes`` is the
    estimate for the whole pass from the part kept before the cap was reached)."""

    lanes: tuple | None
    vertices: int
    nbytes: int
    cap: int
    over_cap: bool = False

    @property
    def usable(self) -> bool:
        return self.lanes is not None and not self.over_cap


class VertexKeeper:
    """Collects the lanes' kept vertices batch by batch (``add``, from any lane's thread), up to
    ``cap`` bytes; past it everything kept is dropped and only the count goes on."""

    def __init__(self, cap: int, lanes: int, total_paths: int):
        self.cap = int(cap)
        self.total_paths = max(int(total_paths), 1)
        self._lanes: list[list] | None = [[] for _ in range(lanes)]
        self._lock = threading.Lock()
        self._bases: set[int] = set()
        self.nbytes = 0
        self.vertices = 0
        self.paths = 0  # paths of the batches counted

    @property
    def keeping(self) -> bool:
        return self._lanes is not None

    def add(self, lane: int, pieces: list | None, paths: int) -> None:
        """Lane ``lane``'s next batch: ``pieces`` (lists of SplatVertices per SPLIT piece) of ``paths`` paths."""
        if pieces is None:
            return
        size = count = 0
        bases = []
        for piece in pieces:
            for v in piece:
                size += v.nbytes
                count += len(v)
                if v.basis is not None:
                    bases.append(v.basis)
        with self._lock:
            for b in bases:  # a white population's shared spectra, once each
                if id(b) not in self._bases:
                    self._bases.add(id(b))
                    size += b.nbytes
            self.nbytes += size
            self.vertices += count
            self.paths += int(paths)
            if self._lanes is None:
                return
            if self.nbytes > self.cap:
                self._lanes = None  # over the cap: keep nothing (the memory is freed)
                self._bases.clear()
                return
            self._lanes[lane].append(tuple(tuple(p) for p in pieces))

    def store(self) -> SplatVertexStore:
        if self._lanes is None:  # the pass's bytes, extrapolated from the part counted
            estimate = int(self.nbytes * self.total_paths / max(self.paths, 1))
            return SplatVertexStore(None, self.vertices, estimate, self.cap, over_cap=True)
        return SplatVertexStore(tuple(tuple(lane) for lane in self._lanes), self.vertices, self.nbytes, self.cap)


def resplat_note(store: SplatVertexStore | None) -> str:
    """Why ``store`` cannot be splatted into another camera ("" when it can)."""
    if store is None:
        return "the kept light pass kept no camera-splat vertices"
    if store.over_cap:
        return (f"the camera splat's vertices ({store.nbytes / 2**20:.0f} MB) are over the "
                f"{store.cap / 2**20:.0f} MB cap")
    return ""


@one_blas_thread()  # the lanes are the parallelism, as the light pass's (core/util/blas_threads.py)
def resplat(prepared, light, threads: int | None = None, should_cancel=None):
    """``light`` (a LightPassResult with usable ``vertices``) with its camera splat made again for
    ``prepared``'s view from the kept vertices (module docstring), or None when ``should_cancel()``
    became true. Its ``resplat`` holds ``resplat_s``, ``resplat_vertices``, ``resplat_bytes`` and
    ``resplat_rays`` (the shadow rays cast); the map, the grating records, the vertices and the
    stats are ``light``'s. ``threads``: lanes re-splatted at once (default ``prepared.threads``,
    at most one per lane)."""
    t0 = time.perf_counter()
    store = light.vertices
    connection = CameraConnection.of(prepared)
    n = prepared.grid.n
    films = [connection.empty() for _ in store.lanes]
    rays = [0] * len(store.lanes)
    stop = threading.Event()

    def run_lane(k):
        film = films[k]
        for batch in store.lanes[k]:
            for piece in batch:
                if stop.is_set() or (should_cancel is not None and should_cancel()):
                    stop.set()
                    return
                b = SplatBatch(connection)
                for chunk in piece:
                    b.connect(prepared, chunk, chunk, n)
                film.add_batch(b)
                rays[k] += b.shadow_rays

    workers = max(1, min(len(films), int(prepared.threads if threads is None else threads)))
    if workers == 1:
        for k in range(len(films)):
            run_lane(k)
    else:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            for f in [pool.submit(run_lane, k) for k in range(len(films))]:
                f.result()  # re-raise a lane's exception here
    if stop.is_set():
        return None
    splat = films[0]
    for extra in films[1:]:  # lane order, as light_pass.finish_light_pass
        splat += extra
    info = dict(resplat_s=time.perf_counter() - t0, resplat_vertices=store.vertices, resplat_bytes=store.nbytes,
                resplat_rays=sum(rays))
    return replace(light, splat=splat, resplat=MappingProxyType(info))

"""Pure-NumPy wide BVH ray caster.

Build (vectorised, level by level over all nodes of a level at once, no per-node Python):

1. a binary BVH with a binned SAH (``bins`` bins on each axis, triangle bounding boxes
   binned by centroid), splitting every node with more than ``leaf_size`` triangles;
   segments whose centroids all fall in one bin are split in the middle;
2. collapsed into a ``width``-wide BVH (each wide node adopts up to ``width`` binary
   descendants, always opening the child with the largest surface area first).

Storage is float32 and gather-friendly: ``np.take(a, ids, axis=1)`` fetches everything a
step needs as K-float chunks.

- ``_nodes``: (7, W, K) float32; rows 0-2 child box minima (x, y, z), rows 3-5 maxima,
  row 6 the child reference as int32 bits (>= 0: wide node, < 0: ``~leaf``); unused
  slots have NaN boxes (never hit).  Boxes are rounded outward and padded by a few ulps.
- ``_tris``: (12, L, leaf_size) float32; rows v0, v1, v2, unit geometric normal, columns
  the leaf's triangles (NaN padding for unused columns); ``_leaf_prim`` maps back to input ids.

Traversal is a per-ray depth-first traversal, vectorised across a *pool* of ``pool`` live
rays (per thread): every step each live ray processes one node (slab tests of its K child
boxes; the nearest hit child is visited next, the other hit children are pushed as ONE
compressed stack entry: their slots near-to-far, their count, the node id and the nearest
one's entry distance) or one leaf (all its triangles).  A popped entry whose entry
distance is beyond the closest hit so far is dropped with all its children.  Finished rays
are replaced from a queue of rays sorted by direction octant and a Morton code of origin
and direction (coherent gathers), shared by the worker threads.

Triangle test: the watertight test of Woop, Benthin and Wald (JCGT 2013) in float32:
vertices relative to the ray origin, sheared into the ray's frame, 2D edge functions.  The
projected vertices are bit-identical in every triangle sharing them, so shared edges get
exactly opposite edge functions and vertex fans stay consistent: no slip-through at shared
edges or vertices.  Edges are inclusive.  Distances come from the plane equation.
"""
from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from . import Hits, _as_rays, _as_tmax, _empty_hits, default_threads

_F32 = np.float32
_INT_MAX = np.int32(np.iinfo(np.int32).max)
_BOX_LO = _F32(1 - 4e-6)   # slack on the slab test: accept boxes whose entry is a few
_BOX_HI = _F32(1 + 4e-6)   # ulps beyond their exit (flat boxes, grazing rays)
_MIN_DIR = 1e-30           # |direction component| floor for the reciprocal
_MIN_COS = _F32(1e-6)      # |cos(ray, triangle normal)| below which a ray counts as in-plane
_MAX_BATCH = 1 << 21       # rays sorted and traced per batch (bounds memory for huge calls)
_POP_ROUNDS = 2            # pop rounds per step; rays still popping continue in the next step
_PENDING = -(1 << 62)      # cur[] marker of such rays


# ------------------------------------------------------------------------------------------
# build
# ------------------------------------------------------------------------------------------
def _half_area(lo, hi):
    e = np.maximum(hi - lo, 0.0)
    return e[..., 0] * e[..., 1] + e[..., 1] * e[..., 2] + e[..., 2] * e[..., 0]


def _build_binary(lo, hi, leaf_size, bins):
    """Binary BVH, binned SAH, level by level.  lo/hi: (T,3) triangle boxes.

    Returns perm (T,) and node arrays: left child id (-1 for a leaf; right = left + 1),
    start, count (range in perm), box lo/hi (n,3) float64.  Internally structure-of-arrays
    float32 (reductions along the last axis are much faster in NumPy).
    """
    T = len(lo)
    lo = np.ascontiguousarray(np.asarray(lo, np.float32).T)     # (3, T)
    hi = np.ascontiguousarray(np.asarray(hi, np.float32).T)
    cen = (lo + hi) * np.float32(0.5)
    cap = 2 * T + 1
    left = np.full(cap, -1, np.int64)
    start = np.zeros(cap, np.int64)
    count = np.zeros(cap, np.int64)
    nlo = np.zeros((3, cap), np.float32)
    nhi = np.zeros((3, cap), np.float32)
    perm = np.arange(T)
    start[0], count[0] = 0, T
    nlo[:, 0], nhi[:, 0] = lo.min(axis=1), hi.max(axis=1)
    n_nodes = 1
    active = np.array([0])
    while active.size:
        act = active[count[active] > leaf_size]
        if not act.size:
            break
        st, ct = start[act], count[act]
        M = len(act)
        offs = np.cumsum(ct) - ct
        total = int(ct.sum())
        seg = np.repeat(np.arange(M), ct)
        rank = np.arange(total) - offs[seg]
        pos = st[seg] + rank
        tris = perm[pos]
        c = np.take(cen, tris, axis=1)
        tl = np.take(lo, tris, axis=1)
        th = np.take(hi, tris, axis=1)
        cmin = np.minimum.reduceat(c, offs, axis=1)
        cmax = np.maximum.reduceat(c, offs, axis=1)
        ext = cmax - cmin
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(ext > 0, np.float32(bins) / np.where(ext > 0, ext, 1), 0).astype(np.float32)
        b = ((c - np.take(cmin, seg, axis=1)) * np.take(scale, seg, axis=1)).astype(np.int64)
        np.clip(b, 0, bins - 1, out=b)
        best_cost = np.full(M, np.inf, np.float32)
        best_axis = np.zeros(M, np.int64)
        best_split = np.zeros(M, np.int64)
        rows = np.arange(M)
        segb = seg * bins
        for a in range(3):
            key = segb + b[a]
            order = np.argsort(key, kind="stable")
            ks = key[order]
            run = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
            blo = np.full((3, M * bins), np.inf, np.float32)
            bhi = np.full((3, M * bins), -np.inf, np.float32)
            blo[:, ks[run]] = np.minimum.reduceat(np.take(tl, order, axis=1), run, axis=1)
            bhi[:, ks[run]] = np.maximum.reduceat(np.take(th, order, axis=1), run, axis=1)
            bcnt = np.bincount(key, minlength=M * bins).reshape(M, bins).astype(np.float32)
            blo = blo.reshape(3, M, bins)
            bhi = bhi.reshape(3, M, bins)
            l_lo = np.minimum.accumulate(blo, axis=2)[:, :, :-1]
            l_hi = np.maximum.accumulate(bhi, axis=2)[:, :, :-1]
            r_lo = np.minimum.accumulate(blo[:, :, ::-1], axis=2)[:, :, ::-1][:, :, 1:]
            r_hi = np.maximum.accumulate(bhi[:, :, ::-1], axis=2)[:, :, ::-1][:, :, 1:]
            l_n = np.cumsum(bcnt, axis=1)[:, :-1]
            r_n = np.cumsum(bcnt[:, ::-1], axis=1)[:, ::-1][:, 1:]
            cost = _half_area_soa(l_lo, l_hi) * l_n + _half_area_soa(r_lo, r_hi) * r_n
            cost[(l_n == 0) | (r_n == 0)] = np.inf
            i = np.argmin(cost, axis=1)
            ci = cost[rows, i]
            better = ci < best_cost
            best_cost[better] = ci[better]
            best_axis[better] = a
            best_split[better] = i[better]
        go_left = b[best_axis[seg], np.arange(total)] <= best_split[seg]
        fallback = ~np.isfinite(best_cost)
        if fallback.any():
            fb = fallback[seg]
            go_left[fb] = rank[fb] < (ct[seg[fb]] // 2)
        order = np.argsort(seg * 2 + (~go_left), kind="stable")
        perm[pos] = tris[order]
        n_left = np.bincount(seg, weights=go_left, minlength=M).astype(np.int64)
        L = n_nodes + 2 * np.arange(M)
        R = L + 1
        n_nodes += 2 * M
        left[act] = L
        start[L], count[L] = st, n_left
        start[R], count[R] = st + n_left, ct - n_left
        bounds = np.stack([offs, offs + n_left], axis=1).ravel()
        clo = np.minimum.reduceat(np.take(tl, order, axis=1), bounds, axis=1)
        chi = np.maximum.reduceat(np.take(th, order, axis=1), bounds, axis=1)
        nlo[:, L], nlo[:, R] = clo[:, 0::2], clo[:, 1::2]
        nhi[:, L], nhi[:, R] = chi[:, 0::2], chi[:, 1::2]
        active = np.concatenate([L, R])
    return (perm, left[:n_nodes], start[:n_nodes], count[:n_nodes],
            nlo[:, :n_nodes].T.astype(np.float64), nhi[:, :n_nodes].T.astype(np.float64))


def _half_area_soa(lo, hi):
    e = np.maximum(hi - lo, 0)
    return e[0] * e[1] + e[1] * e[2] + e[2] * e[0]


def _pad_box(lo, hi):
    """Round boxes outward to float32 and pad by a few ulps (and never to zero width)."""
    lo32 = lo - (np.abs(lo) * 2.0**-21 + 1e-30)
    hi32 = hi + (np.abs(hi) * 2.0**-21 + 1e-30)
    lo32 = lo32.astype(np.float32)
    hi32 = hi32.astype(np.float32)
    lo32 = np.nextafter(lo32, _F32(-np.inf))
    hi32 = np.nextafter(hi32, _F32(np.inf))
    return lo32, hi32


def _collapse(left, nlo, nhi, K):
    """Binary tree -> K-wide tree.  Returns (wide_children (W,K) of binary ids, -1 empty),
    and the depth (number of wide levels)."""
    is_inner = left >= 0
    area = _half_area(nlo, nhi)
    area = np.where(is_inner, area, -1.0)  # only inner nodes can be opened
    wide = []
    if not is_inner[0]:
        ent = np.full((1, K), -1, np.int64)
        ent[0, 0] = 0
        return ent, 1
    frontier = np.array([0])   # binary ids that become wide nodes, current level
    depth = 0
    while frontier.size:
        depth += 1
        M = len(frontier)
        ent = np.full((M, K), -1, np.int64)
        ent[:, 0] = left[frontier]
        ent[:, 1] = left[frontier] + 1
        n = np.full(M, 2, np.int64)
        rows = np.arange(M)
        for _ in range(K - 2):
            ea = np.where(ent >= 0, area[np.maximum(ent, 0)], -1.0)
            j = np.argmax(ea, axis=1)
            ok = ea[rows, j] >= 0
            if not ok.any():
                break
            r = rows[ok]
            e = ent[r, j[ok]]
            ent[r, j[ok]] = left[e]
            ent[r, n[r]] = left[e] + 1
            n[r] += 1
        wide.append(ent)
        flat = ent.ravel()
        frontier = flat[(flat >= 0) & is_inner[np.maximum(flat, 0)]]
    return np.concatenate(wide), depth


# ------------------------------------------------------------------------------------------
# accelerator
# ------------------------------------------------------------------------------------------
class NumpyBVH:
    """Pure-NumPy wide BVH.  See the module docstring for the layout and algorithms."""

    name = "numpy"

    def __init__(self, vertices, triangles, width: int = 4, leaf_size: int = 4, bins: int = 16,
                 threads: int | None = None, pool: int = 1 << 16, sort_rays: bool = True):
        if width not in (2, 4):
            raise ValueError("width must be 2 or 4")
        self.width = K = int(width)
        self.leaf_size = Lw = int(leaf_size)
        self.threads = default_threads() if threads is None else max(1, int(threads))
        self.pool = int(pool)
        self.sort_rays = bool(sort_rays)
        self._executor = None
        self._executor_n = 0
        self.stats = None
        v = np.asarray(vertices, np.float32)
        tri_idx = np.asarray(triangles, np.int64).reshape(-1, 3)
        self.n_triangles = T = len(tri_idx)
        if T == 0:
            self._nodes = None
            return
        tv = v[tri_idx]                       # (T,3,3) float32
        tv64 = tv.astype(np.float64)
        lo = tv64.min(axis=1)
        hi = tv64.max(axis=1)
        self.bounds = (lo.min(axis=0), hi.max(axis=0))
        perm, left, start, count, nlo, nhi = _build_binary(lo, hi, Lw, bins)
        wide_ent, depth = _collapse(left, nlo, nhi, K)
        self.depth = depth
        self.stack_size = depth + 2   # one (compressed) entry per level, see _trace_impl

        # ids: wide nodes are binary inner nodes in level order; leaves are binary leaves
        n_bin = len(left)
        is_leaf = left < 0
        leaf_bin = np.flatnonzero(is_leaf)
        leaf_bin = leaf_bin[np.argsort(start[leaf_bin], kind="stable")]  # memory order
        leaf_id = np.full(n_bin, -1, np.int64)
        leaf_id[leaf_bin] = np.arange(len(leaf_bin))
        W = len(wide_ent)
        if is_leaf[0]:
            wide_of_bin = np.full(n_bin, -1, np.int64)
        else:
            inner_order = np.concatenate([[0], wide_ent.ravel()[(wide_ent.ravel() >= 0)
                                                                 & ~is_leaf[np.maximum(wide_ent.ravel(), 0)]]])
            wide_of_bin = np.full(n_bin, -1, np.int64)
            wide_of_bin[inner_order] = np.arange(len(inner_order))
            assert len(inner_order) == W
        ent = wide_ent
        valid = ent >= 0
        e = np.maximum(ent, 0)
        ref = np.where(is_leaf[e], ~leaf_id[e], wide_of_bin[e])
        ref = np.where(valid, ref, 0).astype(np.int32)
        blo, bhi = _pad_box(nlo[e], nhi[e])            # (W,K,3)
        blo[~valid] = np.nan
        bhi[~valid] = np.nan
        nodes = np.empty((W, 7, K), np.float32)
        nodes[:, 0:3, :] = blo.transpose(0, 2, 1)
        nodes[:, 3:6, :] = bhi.transpose(0, 2, 1)
        nodes[:, 6, :] = ref.view(np.float32)
        # (7, W, K): a gather np.take(nodes, ids, axis=1) copies 7 chunks of K floats per node
        self._nodes = np.ascontiguousarray(nodes.transpose(1, 0, 2))
        self._child = self._nodes[6].view(np.int32).reshape(W * K)   # node-major child references
        if W >= 1 << 24:
            raise ValueError("mesh too large for the NumPy BVH (more than 2^24 nodes)")

        # leaves: (nL, 12, Lw) triangle data, NaN padded
        nL = len(leaf_bin)
        ls, lc = start[leaf_bin], count[leaf_bin]
        slot = np.arange(T) - np.repeat(ls, lc)
        lidx = np.repeat(np.arange(nL), lc)
        # leaves sorted by start tile perm positions [0, T) in order
        prim = perm
        tris = np.full((nL, 12, Lw), np.nan, np.float32)
        p_tv = tv[prim]                                   # (T,3,3)
        ng = np.cross(tv64[prim, 1] - tv64[prim, 0], tv64[prim, 2] - tv64[prim, 0])
        ng_len = np.linalg.norm(ng, axis=1, keepdims=True)
        ng = np.where(ng_len > 0, ng / np.where(ng_len > 0, ng_len, 1), 0).astype(np.float32)  # t is scale free
        data = np.concatenate([p_tv.reshape(T, 9), ng], axis=1)   # (T,12)
        tris[lidx, :, slot] = data
        self._tris = np.ascontiguousarray(tris.transpose(1, 0, 2))   # (12, nL, Lw)
        leaf_prim = np.full((nL, Lw), -1, np.int32)
        leaf_prim[lidx, slot] = prim
        self._leaf_prim = leaf_prim
        self.n_nodes = W
        self.n_leaves = nL

    # -- ray ordering -------------------------------------------------------------------------
    def _ray_order(self, o, d):
        """Coherent processing order: direction octant, then a Morton code interleaving the
        origin (10 bits per axis, within the scene bounds) with the direction (7 bits)."""
        lo, hi = self.bounds
        scale = (1023.0 / np.maximum(hi - lo, 1e-30)).astype(np.float32)
        qo = np.clip((o - lo.astype(np.float32)) * scale, 0, 1023).astype(np.uint64)
        qd = np.clip((d + 1.0) * 63.5, 0, 127).astype(np.uint64)
        key = _spread3(qo[:, 0]) << np.uint64(2)
        key |= _spread3(qo[:, 1]) << np.uint64(1)
        key |= _spread3(qo[:, 2])
        key <<= np.uint64(21)
        kd = _spread3(qd[:, 0]) << np.uint64(2)
        kd |= _spread3(qd[:, 1]) << np.uint64(1)
        kd |= _spread3(qd[:, 2])
        key |= kd
        octant = (d[:, 0] < 0).astype(np.uint64) << np.uint64(2)
        octant |= (d[:, 1] < 0).astype(np.uint64) << np.uint64(1)
        octant |= (d[:, 2] < 0).astype(np.uint64)
        key |= octant << np.uint64(51)
        return np.argsort(key)

    # -- traversal ----------------------------------------------------------------------------
    def _trace(self, ray_oi, ray_od, tinit, any_hit, queue, out):
        """Trace the rays handed out by ``queue`` and write results into ``out``.
        ray_oi / ray_od: (6, N) origin + 1/direction, origin + direction, in queue order."""
        with np.errstate(all="ignore"):   # errstate is per thread
            self._trace_impl(ray_oi, ray_od, tinit, any_hit, queue, out)

    def _trace_impl(self, ray_oi, ray_od, tinit, any_hit, queue, out):
        # NumPy notes: boolean-mask indexing a[m] is several times slower than np.compress(m, a)
        # for random masks; a[:, idx] returns a transposed (slow to compute on) layout, so we
        # use np.take(..., axis=1, mode="clip") (indices are valid by construction).
        K = self.width
        Lw = self.leaf_size
        P = max(1, min(self.pool, queue.per_worker))
        S = self.stack_size
        nodes, tris, leaf_prim, child_tab = self._nodes, self._tris, self._leaf_prim, self._child
        kmask = np.int32(~(K - 1))
        kslot = np.arange(K, dtype=np.int32)[:, None]
        net = _SORT_NET[K]
        order = queue.order
        stats = self.stats     # optional counters (set self.stats = collections.Counter())
        take, compress, flatnonzero = np.take, np.compress, np.flatnonzero

        ray_id = np.zeros(P, np.int64)
        rdi = np.zeros((6, P), np.float32)       # origin, 1/direction (SoA) for box tests
        rdl = np.zeros((12, P), np.float32)      # origin, direction, shear rows for triangle tests
        cur = np.zeros(P, np.int64)              # node to visit: >= 0 wide node, < 0 ~leaf
        sp = np.zeros(P, np.int64)
        stack = np.zeros(P * S, np.int64)        # compressed entries, see the push below
        best = np.zeros(P, np.float32)
        bleaf = np.full(P, -1, np.int64)
        bslot = np.zeros(P, np.int64)
        bu = np.zeros(P, np.float32)
        bv = np.zeros(P, np.float32)
        alive = np.zeros(P, bool)
        n_alive = 0
        n_pending = 0
        if any_hit:
            out_occ = out
        else:
            out_t, out_p, out_u, out_v = out

        while True:
            # ---- refill free slots from the queue
            if P - n_alive >= P // 4 or n_alive == 0:
                free = flatnonzero(~alive)
                q0, q1 = queue.take(len(free))
                k = q1 - q0
                if k:
                    free = free[:k]
                    ray_id[free] = order[q0:q1]
                    for row in range(6):
                        rdi[row][free] = ray_oi[row, q0:q1]
                    for row in range(12):
                        rdl[row][free] = ray_od[row, q0:q1]
                    best[free] = tinit[q0:q1]
                    cur[free] = 0
                    sp[free] = 0
                    bleaf[free] = -1
                    alive[free] = True
                    n_alive += k
            if n_alive == 0:
                break
            act = flatnonzero(alive)
            c = take(cur, act)
            leafm = c < 0
            pops = []
            if n_pending:                        # rays that still have to pop (see below)
                pm = c == _PENDING
                pops.append(compress(pm, act))
                leafm &= ~pm
                n_pending = 0
            n_leaf = int(np.count_nonzero(leafm))
            n_inner = len(act) - n_leaf - (len(pops[0]) if pops else 0)

            # ---- inner nodes: test the K child boxes
            if n_inner:
                innm = c >= 0
                si = compress(innm, act)
                ci = compress(innm, c)
                ni = len(si)
                if stats is not None:
                    stats["inner_visits"] += ni
                    stats["steps"] += 1
                g = take(nodes, ci, axis=1, mode="clip")        # (7, ni, K)
                gT = g.transpose(0, 2, 1)                       # (7, K, ni) view
                r = take(rdi, si, axis=1, mode="clip")
                o3 = r[0:3, None, :]
                iv3 = r[3:6, None, :]
                t1 = np.subtract(gT[0:3], o3, out=np.empty((3, K, ni), np.float32))
                t1 *= iv3
                t2 = np.subtract(gT[3:6], o3, out=np.empty((3, K, ni), np.float32))
                t2 *= iv3
                tn = np.minimum(t1, t2)
                tf = np.maximum(t1, t2, out=t2)
                tnear = np.maximum(tn[0], tn[1])
                np.maximum(tnear, tn[2], out=tnear)
                np.maximum(tnear, 0, out=tnear)
                tfar = np.minimum(tf[0], tf[1])
                np.minimum(tfar, tf[2], out=tfar)
                tfar *= _BOX_HI
                np.minimum(tfar, take(best, si), out=tfar)
                tnear_lo = tnear * _BOX_LO
                hit = tnear_lo <= tfar                          # (K, ni)
                # sort keys: entry distance (as int bits, >= 0) with the child slot in the low bits
                key = tnear.view(np.int32)
                key &= kmask
                key |= kslot
                key = np.where(hit, key, _INT_MAX)
                ks = list(key)
                for x, y in net:
                    kx, ky = ks[x], ks[y]
                    ks[x] = np.minimum(kx, ky)
                    ks[y] = np.maximum(kx, ky)
                h8 = hit.view(np.uint8)
                cnt = h8[0] + h8[1]
                for j in range(2, K):
                    cnt += h8[j]
                child = g[6].view(np.int32).reshape(ni * K)     # ray-major
                cols = np.arange(0, ni * K, K)
                # visit the nearest hit child next (garbage if cnt == 0: popped below)
                cur[si] = take(child, (ks[0] & (K - 1)) + cols, mode="clip")
                # push ONE entry for the other hit children: their slots in near-to-far order,
                # how many, this node's id and the entry distance of the nearest of them
                m = cnt > 1
                sm = compress(m, si)
                if len(sm):
                    k1 = compress(m, ks[1])
                    code = k1 & (K - 1)
                    if K == 4:
                        code |= (compress(m, ks[2]) & 3) << 2
                        code |= (compress(m, ks[3]) & 3) << 4
                    code |= (compress(m, cnt).astype(np.int32) - 1) << 6
                    ent = ((k1 & kmask) & 0x7FFFFFFF).astype(np.int64) << 32
                    ent |= compress(m, ci) << 8
                    ent |= code
                    spm = take(sp, sm)
                    stack[sm * S + spm] = ent
                    sp[sm] = spm + 1
                pops.append(compress(cnt == 0, si))

            # ---- leaves: test their triangles
            if n_leaf:
                sl = compress(leafm, act)
                nl = len(sl)
                if stats is not None:
                    stats["leaf_visits"] += nl
                lf = ~compress(leafm, c)
                tr = take(tris, lf, axis=1, mode="clip").transpose(0, 2, 1)   # (12, Lw, nl) view
                r = take(rdl, sl, axis=1, mode="clip")
                o3 = r[0:3, None, :]
                # watertight test (Woop, Benthin, Wald 2013): vertices relative to the origin,
                # sheared/projected into the ray's frame.  The per-ray coefficient rows mx, my
                # hold 1 and -S at the permuted axes and exact zeros elsewhere, so each projected
                # vertex is bit-identical for every triangle sharing it: shared edges get exactly
                # opposite edge functions and vertex fans stay consistent (no slip-through).
                mx0, mx1, mx2, my0, my1, my2 = r[6], r[7], r[8], r[9], r[10], r[11]
                proj = []
                for k in range(3):
                    a = np.subtract(tr[3 * k:3 * k + 3], o3, out=np.empty((3, Lw, nl), np.float32))
                    px = a[0] * mx0
                    px += a[1] * mx1
                    px += a[2] * mx2
                    py = a[0] * my0
                    py += a[1] * my1
                    py += a[2] * my2
                    proj.append((px, py))
                    if k == 0:
                        a0 = a
                (ax, ay), (bx, by), (cx, cy) = proj
                U = cx * by
                U -= cy * bx                      # edge v1-v2: weight of v0
                V = ax * cy
                V -= ay * cx                      # edge v2-v0: weight of v1
                Wf = bx * ay
                Wf -= by * ax                     # edge v0-v1: weight of v2
                uvw = U + V
                uvw += Wf
                mn = np.minimum(U, V)
                np.minimum(mn, Wf, out=mn)
                mx = np.maximum(U, V)
                np.maximum(mx, Wf, out=mx)
                inside = mn >= 0                  # edges inclusive
                inside |= mx <= 0
                inside &= uvw != 0                # all three underflowed (a ~1e-20 m triangle): no hit
                # distance from the plane equation (unit normal), independent of the shear
                dx, dy, dz = r[3], r[4], r[5]
                ngx, ngy, ngz = tr[9], tr[10], tr[11]
                den = ngx * dx
                den += ngy * dy
                den += ngz * dz
                tt = a0[0] * ngx
                tt += a0[1] * ngy
                tt += a0[2] * ngz
                tt /= den
                bl = take(best, sl)
                ok = tt > 0
                ok &= inside
                ok &= tt < bl
                # rays (numerically) inside the triangle's plane: U, V, W and t are rounding
                # noise there (Embree has the same blind spot), so grazing hits are ignored
                ok &= np.abs(den) >= _MIN_COS
                if any_hit:
                    occ = ok.any(axis=0)
                    fin = compress(occ, sl)
                    if len(fin):
                        out_occ[take(ray_id, fin)] = True
                        alive[fin] = False
                        n_alive -= len(fin)
                        pops.append(compress(~occ, sl))
                    else:
                        pops.append(sl)
                else:
                    tt = np.where(ok, tt, np.inf)
                    tj = tt[0]                    # closest over the leaf's slots (np.argmin along
                    j = np.zeros(nl, np.int64)    # axis 0 is very slow)
                    for jj in range(1, Lw):
                        lt = tt[jj] < tj
                        tj = np.where(lt, tt[jj], tj)
                        j[lt] = jj
                    cols = np.arange(nl)
                    better = tj < bl
                    cb = flatnonzero(better)
                    if len(cb):
                        jb = take(j, cb)
                        sb = take(sl, cb)
                        best[sb] = take(tj, cb)
                        bleaf[sb] = take(lf, cb)
                        bslot[sb] = jb
                        w_sum = uvw[jb, cb]
                        inv = 1.0 / w_sum
                        vb, wb = V[jb, cb], Wf[jb, cb]
                        tiny = ~np.isfinite(inv)  # a subnormal sum (triangles of ~1e-20 m): divide
                        bu[sb] = np.where(tiny, vb / np.where(tiny, w_sum, 1), vb * inv)  # Embree's u, v:
                        bv[sb] = np.where(tiny, wb / np.where(tiny, w_sum, 1), wb * inv)  # weights of v1, v2
                    pops.append(sl)

            # ---- pop: take the next child of the top entry; an entry whose (nearest) entry
            # distance is beyond the best hit is dropped with all its children
            p = np.concatenate(pops) if len(pops) > 1 else (pops[0] if pops else act[:0])
            fins = []
            for _round in range(_POP_ROUNDS):
                if not len(p):
                    break
                spp = take(sp, p)
                empty = spp == 0
                if empty.any():
                    fins.append(compress(empty, p))
                    keep = ~empty
                    p = compress(keep, p)
                    spp = compress(keep, spp)
                spp -= 1
                idx = p * S + spp
                e = take(stack, idx)
                tn = (e >> 32).astype(np.int32).view(np.float32)
                ok = tn <= take(best, p)
                okw = flatnonzero(ok)
                eq = take(e, okw)
                code = eq & 0xFF
                cur[take(p, okw)] = take(child_tab, ((eq >> 8) & 0xFFFFFF) * K + (code & (K - 1)), mode="clip")
                more = code >= 128               # more than one child left in the entry
                mw = flatnonzero(more)
                if len(mw):                      # drop the popped slot, keep the entry
                    cm = take(code, mw)
                    stack[take(idx, take(okw, mw))] = ((take(eq, mw) & ~np.int64(0xFF))
                                                      | ((cm & 0x3F) >> 2) | (((cm >> 6) - 1) << 6))
                    spp[take(okw, mw)] += 1
                sp[p] = spp
                p = compress(~ok, p)
            if len(p):                           # few rays, many rounds: continue next step
                cur[p] = _PENDING
                n_pending = len(p)
            if fins:
                fin = np.concatenate(fins) if len(fins) > 1 else fins[0]
                alive[fin] = False
                n_alive -= len(fin)
                if not any_hit:
                    bl = take(bleaf, fin)
                    hw = flatnonzero(bl >= 0)
                    if len(hw):
                        f = take(fin, hw)
                        rid = take(ray_id, f)
                        out_t[rid] = take(best, f)
                        out_p[rid] = leaf_prim[take(bl, hw), take(bslot, f)]
                        out_u[rid] = take(bu, f)
                        out_v[rid] = take(bv, f)

    def _run(self, origins, directions, tmax, any_hit):
        o, d = _as_rays(origins, directions)
        n = len(o)
        tm = _as_tmax(tmax, n)
        if any_hit:
            out = np.zeros(n, bool)
            if self._nodes is None or n == 0:
                return out
            tinit = tm
        else:
            if self._nodes is None or n == 0:
                return _empty_hits(n)
            out = (np.full(n, np.inf, np.float32), np.full(n, -1, np.int32),
                   np.zeros(n, np.float32), np.zeros(n, np.float32))
            tinit = np.nextafter(tm, _F32(np.inf))   # accept t == tmax
        for s0 in range(0, n, _MAX_BATCH):       # bound the per-call memory (~100 bytes/ray)
            sl = slice(s0, min(n, s0 + _MAX_BATCH))
            part = out[sl] if any_hit else tuple(a[sl] for a in out)
            self._run_batch(o[sl], d[sl], tinit[sl], any_hit, part)
        if any_hit:
            return out
        return Hits(*out)

    def _run_batch(self, o, d, tinit, any_hit, out):
        n = len(o)
        if self.sort_rays and n > 4096:
            with np.errstate(all="ignore"):      # NaN/inf rays just sort somewhere
                order = self._ray_order(o, d)
        else:
            order = np.arange(n)
        nthreads = min(self.threads, max(1, n // 16384))
        queue = _Queue(order, nthreads)
        # per-ray data in queue order, structure of arrays
        ray_od = np.empty((12, n), np.float32)
        ray_od[0:3] = o[order].T
        ray_od[3:6] = d[order].T
        dd = ray_od[3:6]
        ray_oi = np.empty((6, n), np.float32)
        ray_oi[0:3] = ray_od[0:3]
        with np.errstate(all="ignore"):
            np.divide(1.0, np.where(np.abs(dd) < _MIN_DIR, np.where(dd < 0, -_MIN_DIR, _MIN_DIR), dd),
                      out=ray_oi[3:6])
            # shear rows of the watertight test: x' = a.mx, y' = a.my with
            # mx = e_kx - (d_kx/d_kz) e_kz, my = e_ky - (d_ky/d_kz) e_kz, kz = argmax |d|
            kz = np.argmax(np.abs(dd), axis=0)
            kx = (kz + 1) % 3
            ky = (kz + 2) % 3
            cols = np.arange(n)
            dkz = dd[kz, cols]
            ray_od[6:12] = 0
            ray_od[6 + kx, cols] = 1
            ray_od[6 + kz, cols] = -(dd[kx, cols] / dkz)
            ray_od[9 + ky, cols] = 1
            ray_od[9 + kz, cols] = -(dd[ky, cols] / dkz)
        tinit = tinit[order]
        if nthreads <= 1:
            self._trace(ray_oi, ray_od, tinit, any_hit, queue, out)
        else:
            # every thread runs its own ray pool and refills it from the shared queue
            if self._executor is None or self._executor_n != nthreads:
                if self._executor is not None:
                    self._executor.shutdown(wait=False)
                self._executor = ThreadPoolExecutor(nthreads, thread_name_prefix="opal-bvh")
                self._executor_n = nthreads
            futs = [self._executor.submit(self._trace, ray_oi, ray_od, tinit, any_hit, queue, out)
                    for _ in range(nthreads)]
            for f in futs:
                f.result()

    def intersect(self, origins, directions, tmax=None) -> Hits:
        return self._run(origins, directions, tmax, any_hit=False)

    def occluded(self, origins, directions, tmax) -> np.ndarray:
        return self._run(origins, directions, tmax, any_hit=True)

    def __del__(self):
        ex = getattr(self, "_executor", None)
        if ex is not None:
            ex.shutdown(wait=False)


def _spread3(x):
    """Insert two zero bits between the low 10 bits of x (uint64): the Morton 'part1by2'."""
    x = x & np.uint64(0x3FF)
    x = (x | (x << np.uint64(16))) & np.uint64(0x030000FF)
    x = (x | (x << np.uint64(8))) & np.uint64(0x0300F00F)
    x = (x | (x << np.uint64(4))) & np.uint64(0x030C30C3)
    x = (x | (x << np.uint64(2))) & np.uint64(0x09249249)
    return x


class _Queue:
    """Thread-safe queue of ray indices, handed out in contiguous (coherent) blocks."""

    def __init__(self, order, workers=1):
        self.order = order
        self.per_worker = -(-len(order) // workers)
        self.pos = 0
        self.lock = threading.Lock()

    def take(self, k):
        """Reserve the next k rays: returns the range [start, stop) of queue positions."""
        with self.lock:
            s = self.pos
            self.pos = min(len(self.order), s + k)
            return s, self.pos


# sorting networks (compare-exchange pairs) for the K child keys
_SORT_NET = {
    2: [(0, 1)],
    4: [(0, 1), (2, 3), (0, 2), (1, 3), (1, 2)],
}

"""The light pass's compiled kernels (core/util/jit.py) against their NumPy references.

The camera splat's kernels (core/integrators/light/camera_splat.py: the filter footprint, the
per-pixel sums of a batch, the film's add) do the reference's operations in its order and
precision, so they must give the same bits. Whole light passes on the kernels and on the
reference are compared on the README's prism (a caustic scene: light dispersed by glass onto
a wall), and a light pass on the kernels must not depend on the number of threads.
"""

from __future__ import annotations

import numpy as np
import pytest

from opal_diffraction._scripts import load_example
from opal_diffraction.core.integrators.light.camera_splat import CameraConnection, MonoContributions, SplatBatch
from opal_diffraction.core.integrators.light.light_pass import run_light_pass
from opal_diffraction.core.render.plan import plan_render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.settings import RenderSettings
from opal_diffraction.core.transport.walker import Hit, Rays
from opal_diffraction.core.util import jit

pytestmark = pytest.mark.skipif(not jit.AVAILABLE, reason=f"no JIT: {jit.UNAVAILABLE_REASON}")


def both(fn, *args):
    """(kernel result, NumPy reference result) of fn(*args)."""
    assert jit.kernels_enabled()
    got = fn(*args)
    with jit.kernel_mode("numpy"):
        assert not jit.kernels_enabled()
        want = fn(*args)
    return got, want


def same_bits(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape
    assert np.array_equal(a.view(np.uint8), b.view(np.uint8))


def prism(width=64, height=40, **kw):
    scene = load_example("prism").build_scene(width, height)
    return prepare(scene, RenderSettings(samples=1, wavelength_step=kw.pop("wavelength_step", 10.0), **kw))


@pytest.fixture(scope="module")
def connection():
    return CameraConnection.of(prism())


def image_points(conn, b, rng):
    """Image positions over the image and a filter's width beyond it, with exact pixel edges and centres."""
    fw = conn.filter_width
    x = rng.uniform(-fw, conn.width + fw, b)
    y = rng.uniform(-fw, conn.height + fw, b)
    x[:8] = [0.0, 0.5, conn.width, conn.width - 0.5, -fw + 1e-9, conn.width + fw - 1e-9, 3.0, 3.5]
    y[:8] = [0.5, 0.0, conn.height - 0.5, conn.height, 2.0, 2.5, -fw + 1e-9, conn.height + fw - 1e-9]
    return x, y


def test_footprint_kernel_is_the_reference_bit_for_bit(connection):
    x, y = image_points(connection, 5000, np.random.default_rng(1))
    (gi, gw), (wi, ww) = both(connection.footprint, x, y)
    same_bits(gi, wi)
    same_bits(gw, ww)
    assert (ww > 0).any() and (ww == 0).any()  # the edges: weights outside the image are zero


def splat_calls(conn, rng, channels, spectral):
    """A batch's splat calls: white (dense) and mono landings in turn, many on the same pixels."""
    calls = []
    for k in range(6):
        b = int(rng.integers(1, 400))
        x, y = image_points(conn, b, rng)
        x[: b // 2] = rng.uniform(10, 12, b // 2)  # a caustic: many landings on few pixels
        y[: b // 2] = rng.uniform(10, 11, b // 2)
        idx, w = conn.footprint(x, y)
        if k % 2 == 0 or not spectral:
            c = rng.exponential(1.0, (b, channels))
            c[0] = 0.0
            calls.append((idx, w, c, c))
        else:
            lam = rng.integers(0, channels, b)
            v = rng.exponential(1.0, b)
            mono = MonoContributions(lam, v)
            calls.append((idx, w, mono, mono.dense(channels)))
    return calls


@pytest.mark.parametrize("spectral", [True, False])
def test_batch_sums_per_pixel_are_the_reference_bit_for_bit(connection, spectral):
    channels = connection.channels if spectral else 3
    calls = splat_calls(connection, np.random.default_rng(2 + spectral), channels, spectral)

    def finish(kernel):
        batch = SplatBatch(connection)
        batch.connection = type("C", (), {"channels": channels, "width": connection.width,
                                          "height": connection.height})()
        batch._calls = [(p, q, kv if kernel else dense) for p, q, kv, dense in calls]
        return batch.finish()

    got = finish(True)
    with jit.kernel_mode("numpy"):
        want = finish(False)
        mixed = finish(True)  # the kernels' mono form summed by the reference
    for g, w, m in zip(got, want, mixed):
        same_bits(g, w)
        same_bits(m, w)
    assert len(want[0]) > 0 and np.all(np.diff(want[0]) > 0)


def test_film_add_of_a_batch_is_the_reference_bit_for_bit(connection):
    """CameraSplat.add_batch (the sums rounded and added in one pass) = add(*finish()) of the reference."""
    calls = splat_calls(connection, np.random.default_rng(9), connection.channels, True)

    def add(kernel):
        film = connection.empty()
        film.image[...] = np.float32(0.3)
        for _ in range(2):
            batch = SplatBatch(connection)
            batch._calls = [(p, q, kv if kernel else dense) for p, q, kv, dense in calls]
            film.add_batch(batch)
        return film.image

    got = add(True)
    with jit.kernel_mode("numpy"):
        want = add(False)
    same_bits(got, want)
    assert (want != np.float32(0.3)).any()


def test_empty_batch(connection):
    (gp, gv), (wp, wv) = both(SplatBatch(connection).finish)
    same_bits(gp, wp)
    same_bits(gv, wv)


def test_film_add_is_the_reference_bit_for_bit(connection):
    rng = np.random.default_rng(3)
    pixels = np.sort(rng.choice(connection.width * connection.height, 300, replace=False))
    values = rng.exponential(1.0, (300, connection.channels)).astype(np.float32)

    def add():
        film = connection.empty()
        film.image[...] = np.float32(0.1)
        film.add(pixels, values)
        film.add(pixels[::2], values[::2])
        return film.image

    got, want = both(add)
    same_bits(got, want)


def landings(prepared, rng, b, mono):
    """Light-path landings on the scene's triangles facing the camera or not, white or mono."""
    v, t = prepared.scene.vertices, prepared.scene.triangles
    tri = rng.integers(0, len(t), b)
    bu, bv = rng.uniform(0, 0.5, b), rng.uniform(0, 0.5, b)
    p = ((1 - bu - bv)[:, None] * v[t[tri, 0]] + bu[:, None] * v[t[tri, 1]] + bv[:, None] * v[t[tri, 2]])
    ng = prepared.tri_normal[tri] * np.where(rng.random(b) < 0.5, 1, -1).astype(np.float32)[:, None]
    hit = Hit(p.astype(np.float32), ng, ng, np.ones(b, np.float32), np.ones(b, bool), prepared.tri_material[tri],
              prepared.tri_offset[tri], tri.astype(np.int32), bu.astype(np.float32), bv.astype(np.float32))
    n = prepared.grid.n
    d = np.tile(np.float32([0, 0, -1]), (b, 1))
    if mono:
        rays = Rays(p.astype(np.float32), d, np.zeros(b, np.int64), rng.exponential(1, b).astype(np.float32),
                    rng.integers(0, n, b), np.ones(b, np.int32), rng.random(b))
    else:
        rays = Rays(p.astype(np.float32), d, np.zeros(b, np.int64), rng.exponential(1, (b, n)).astype(np.float32),
                    None, np.ones(b, np.int32), rng.random(b))
    return rays, hit


@pytest.mark.parametrize("mono", [False, True])
@pytest.mark.parametrize("spectral", [True, False])
def test_connect_kernels_agree_with_the_reference(mono, spectral):
    """The camera connection's projection and shadow rays on the kernel: sums of three products
    where the reference has BLAS / einsum (their order and FMA are the library's), and cos^3 as
    two products where the reference calls pow: a few ulps (rtol 1e-12) on the weights and
    contributions; the same landings kept and the same pixels."""
    prepared = prism()
    conn = CameraConnection.of(prepared)
    if not spectral:
        conn = CameraConnection(**dict(conn.__dict__, rgb_weights=prepared.conv.rgb_weights.astype(np.float64),
                                       channels=3))
    rays, hit = landings(prepared, np.random.default_rng(5 + mono), 4000, mono)
    ((gi, gw, gc), gn), ((wi, ww, wc), wn) = both(conn.connect, prepared, rays, hit, prepared.grid.n)
    assert gn == wn and gn > 100 and len(wc) > 100  # shadow rays cast, landings splatted
    same_bits(gi, wi)
    np.testing.assert_allclose(gw, ww, rtol=1e-12, atol=0)
    gc = gc.dense(conn.channels) if isinstance(gc, MonoContributions) else gc
    np.testing.assert_allclose(gc, wc, rtol=1e-12, atol=0)


# ------------------------------------------------------------------------------ whole light passes
def light_pass(mode, threads=1, paths=40_000):
    with jit.kernel_mode(mode):
        prepared = prism(threads=threads, kernels=mode)
        return run_light_pass(prepared, paths, plan=plan_render(prepared))


@pytest.fixture(scope="module")
def passes():
    return {"auto": light_pass("auto"), "numpy": light_pass("numpy"), "auto2": light_pass("auto", threads=2)}


def test_light_pass_on_kernels_is_the_same_for_any_thread_count(passes):
    a, b = passes["auto"], passes["auto2"]
    same_bits(a.caustics.flux, b.caustics.flux)
    same_bits(a.splat.image, b.splat.image)
    assert a.stats["light_rays"] == b.stats["light_rays"]


def z_scores(a, b, k=8):
    """Per-block Z of the difference of two independent-or-equal estimates (H, W[, C]) summed
    over k x k pixel blocks and channels, scaled by the blocks' spread (a Poisson-like bound)."""
    def blocks(img):
        img = img.reshape(img.shape[0], img.shape[1], -1).sum(axis=2)
        h, w = (img.shape[0] // k) * k, (img.shape[1] // k) * k
        return img[:h, :w].reshape(h // k, k, w // k, k).sum(axis=(1, 3))
    ba, bb = blocks(a.astype(np.float64)), blocks(b.astype(np.float64))
    scale = np.sqrt(np.maximum(ba, 0) + np.maximum(bb, 0)) * np.sqrt(max(ba.max(), bb.max(), 1e-300))
    return np.where(scale > 0, (ba - bb) / np.where(scale > 0, scale, 1.0), 0.0)


def test_light_pass_on_kernels_equals_the_reference_on_a_caustic_scene(passes):
    a, b = passes["auto"], passes["numpy"]
    assert b.splat.image.max() > 0 and b.caustics.flux.max() > 0  # the prism throws a spectrum on the wall
    assert a.stats["light_paths"] == b.stats["light_paths"]
    # the map: totals per wavelength within noise, and the camera's view of it block by block
    fa, fb = a.caustics.flux.astype(np.float64), b.caustics.flux.astype(np.float64)
    np.testing.assert_allclose(fa.sum(axis=0), fb.sum(axis=0), rtol=0.02, atol=1e-3 * fb.sum(axis=0).max())
    z = z_scores(a.splat.image, b.splat.image)
    assert np.abs(z).max() < 4.0, np.abs(z).max()


def glass_balls_scene():
    """Two glass balls and a mirror cube (three caster objects) over a floor, lit by an area light and
    a sized point light: the paths of per-path-origin cone sampling, where kernels and reference
    differ in the last bits (tests/lights/test_light_aiming_kernels.py)."""
    mats = Materials.from_list([{"kind": "DIFFUSE", "color": (0.6, 0.6, 0.6)},
                                {"kind": "DIELECTRIC", "ior": 1.5, "color": (1, 1, 1)},
                                {"kind": "MIRROR", "color": (0.9, 0.9, 0.9)}])
    s = Scene(materials=mats)
    s.add_mesh(*primitives.quad((0, 0, 0), (6, 0, 0), (0, 6, 0)), material=0)
    s.add_mesh(*primitives.icosphere((-0.6, 0, 0.5), 0.4, 2), material=1)
    s.add_mesh(*primitives.icosphere((0.6, 0.3, 0.4), 0.3, 2), material=1)
    s.add_mesh(*primitives.box((0.2, -0.9, 0.25), (0.5, 0.5, 0.5)), material=2)
    s.lights = Lights.from_list([
        {"kind": "AREA_RECT", "position": (0.3, 0.2, 2.5), "direction": (0, 0, -1), "size_u": 0.4, "size_v": 0.3,
         "power": 40.0},
        {"kind": "POINT", "position": (-1.5, 1.0, 2.0), "radius": 0.1, "power": 30.0}])
    s.camera = Camera.look_at((0, -3.5, 3.0), (0, 0, 0.2), width=64, height=48)
    return s


def test_light_pass_on_kernels_is_the_reference_within_noise_with_area_and_sized_lights():
    """Kernel and reference paths may start a few float64 ulps apart (the aiming kernels' sums;
    the rays are float32, which mostly rounds the difference away), so after the glass a path
    may land elsewhere: the maps must be equal within noise (tighter: bit for bit, as they are
    on this machine, passes too). Per-wavelength totals, and the camera's view of the splat by
    blocks of pixels against the spread of two independent passes (the reference at another seed)."""
    def run(mode, seed):
        with jit.kernel_mode(mode):
            prepared = prepare(glass_balls_scene(), RenderSettings(samples=1, wavelength_step=40.0, seed=seed,
                                                                   kernels=mode))
            return run_light_pass(prepared, 60_000, plan=plan_render(prepared))

    got, want, other = run("auto", 1), run("numpy", 1), run("numpy", 2)
    assert want.caustics.flux.max() > 0 and want.splat.image.max() > 0

    def blocks(img, k=8):
        img = img.astype(np.float64).sum(axis=2)
        return img.reshape(img.shape[0] // k, k, img.shape[1] // k, k).sum(axis=(1, 3)).ravel()

    g, w, o = blocks(got.splat.image), blocks(want.splat.image), blocks(other.splat.image)
    spread = np.abs(o - w) + 1e-3 * w.max()  # one independent pass's difference: the noise's scale
    assert np.abs(g - w).max() <= 4.0 * spread.max()
    assert np.abs(g - w).sum() < 0.5 * np.abs(o - w).sum()  # mostly the same paths: far below noise
    fg, fw_ = got.caustics.flux.sum(axis=0), want.caustics.flux.sum(axis=0)
    np.testing.assert_allclose(fg, fw_, rtol=0.02)

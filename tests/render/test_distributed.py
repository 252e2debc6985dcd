"""One frame on Dask (core/render/distributed.py): a LocalCluster of 2 worker processes renders the
image, the spectral film (and its EXR) and the passes of a single-process render bit for bit,
also when a worker is killed mid-render; cancel stops it; the core never imports dask unasked;
the wire format names none of our modules."""

from __future__ import annotations

import dataclasses
import os
import pickle
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from opal_diffraction.core.scene import primitives
from opal_diffraction.core.render.distributed import (TILE_TASK, ClusterError, connect, from_wire, pack_map, to_wire,
                                               unpack_map)
from opal_diffraction.core.integrators.light.light_pass import LightWork, run_light_pass
from opal_diffraction.core.render.output import write_spectral_exr
from opal_diffraction.core.render.plan import plan_render
from opal_diffraction.core.render.prepare import prepare
from opal_diffraction.core.render.frame import render
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.npz import save_scene
from opal_diffraction.core.scene.settings import RenderSettings

SETTINGS = RenderSettings(samples=4, round_samples=2, light_paths=150_000, seed=11, threads=2, tile_size=8)


def every_pass_scene(width=32, height=24) -> Scene:
    """A dispersive glass block over a floor and a reflection grating, under a point light:
    the light pass deposits caustics on the floor and records on the grating; the eye pass sees
    direct light, caustics, diffraction and the world."""
    mats = Materials.from_list([
        {"kind": "DIFFUSE", "color": (0.6, 0.6, 0.6)},
        {"kind": "DIELECTRIC", "ior": 1.5, "dispersion": "BK7", "color": (1, 1, 1)},
        {"kind": "DIFFUSE", "color": (0.1, 0.1, 0.1), "grating": 1, "grating_type": "REFLECTION",
         "period": 1600.0, "slit_width": 800.0, "slit_count": 200, "coherence_length": 10.0},
    ])
    s = Scene(materials=mats, world_color=np.array([0.03, 0.03, 0.04], np.float32))
    s.add_mesh(*primitives.quad((-1, 0, 0), (6, 0, 0), (0, 6, 0)), material=0)
    s.add_mesh(*primitives.quad((1.0, 0, 0.001), (1.6, 0, 0), (0, 1.6, 0)), material=2, tangent=(1, 0, 0))
    s.add_mesh(*primitives.box((0.3, 0.0, 0.8), (0.8, 0.8, 0.4)), material=1)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0.6, -0.2, 3.0), "power": 1500.0}])
    s.camera = Camera.look_at((0.3, -3.5, 2.5), (0.4, 0, 0.3), width=width, height=height)
    return s


def assert_identical(a, b):
    assert (a.spectral is None) == (b.spectral is None)  # tiles cross the wire as RGB unless spectral is asked
    if a.spectral is not None:
        np.testing.assert_array_equal(a.spectral, b.spectral)
    np.testing.assert_array_equal(a.rgb, b.rgb)
    np.testing.assert_array_equal(a.alpha, b.alpha)  # the coverage crosses the wire with the tiles
    assert a.passes.keys() == b.passes.keys()
    for k in a.passes:
        np.testing.assert_array_equal(a.passes[k], b.passes[k], err_msg=k)
    assert a.samples == b.samples and a.cancelled == b.cancelled


@pytest.fixture(scope="module")
def local():
    return render(every_pass_scene(), SETTINGS, spectral_film=True)


@pytest.fixture(scope="module")
def client():
    pytest.importorskip("distributed")
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as c:
        yield c


def _opal_keys(client) -> list:
    return client.run_on_scheduler(lambda dask_scheduler: [str(k) for k in dask_scheduler.tasks
                                                           if str(k).startswith("opal-")])


def _wait_until_forgotten(client, timeout=10.0) -> list:
    t0 = time.perf_counter()
    while (left := _opal_keys(client)) and time.perf_counter() - t0 < timeout:
        time.sleep(0.05)
    return left


def test_the_scene_exercises_every_pass():
    """Without this the identity tests below would prove less than they claim."""
    prepared = prepare(every_pass_scene(), SETTINGS)
    plan = plan_render(prepared)
    assert plan.light_pass and plan.gratings and plan.dispersion
    light = run_light_pass(prepared, plan=plan_render(prepared))
    assert light.caustics.flux.sum() > 0 and light.grating_records.flux.sum() > 0
    assert light.splat is not None and light.splat.image.sum() > 0  # caustics the camera sees directly, splatted
    assert len(LightWork.of(prepared).batches) >= 4  # several light tasks, both lanes used


@pytest.mark.slow
def test_two_worker_processes_render_the_single_process_image_bit_for_bit(client, local, tmp_path):
    assert all(local.passes[k].max() > 0 for k in ("Direct", "Caustics", "Diffraction"))
    progress = []
    dist = render(every_pass_scene(), SETTINGS, client=client, progress=lambda f, m: progress.append(f), spectral_film=True)
    assert_identical(local, dist)
    assert dist.stats["workers"] == 2 and dist.stats["light_tasks"] >= 4 and dist.stats["eye_tasks"] == 24
    assert dist.stats["light_deposits"] == local.stats["light_deposits"]
    assert progress and progress[-1] == pytest.approx(1.0) and progress == sorted(progress)
    # the spectral EXR, byte for byte
    for name, r in (("local", local), ("dist", dist)):
        write_spectral_exr(str(tmp_path / f"{name}.exr"), r.spectral, r.wavelengths, r.rgb)
    assert (tmp_path / "local.exr").read_bytes() == (tmp_path / "dist.exr").read_bytes()
    # a border render too (tiles carry the region; RGB tiles: no spectral film), and nothing is left on
    # the scheduler
    region = (5, 3, 29, 20)
    assert_identical(render(every_pass_scene(), SETTINGS, region=region),
                     render(every_pass_scene(), SETTINGS, region=region, client=client))
    assert _wait_until_forgotten(client) == []


def _kill_a_busy_worker(client, killed: list) -> None:
    """SIGKILL a worker process that is running a task of ours (its nanny starts a new one)."""
    pids = client.run(os.getpid)
    processing = client.processing()
    busy = [w for w, keys in processing.items() if any(str(k).startswith("opal-") for k in keys)]
    victim = (busy or sorted(pids))[0]
    killed.append(pids[victim])
    os.kill(pids[victim], signal.SIGKILL)


@pytest.mark.slow
@pytest.mark.parametrize("phase", ["light pass", "eye pass"])
def test_a_worker_killed_mid_render_changes_nothing(client, local, phase):
    """A worker killed while light batches (or tiles) are pending: Dask reruns its tasks on the
    other worker, and on its replacement, with the same random streams; the image is the same."""
    client.wait_for_workers(2, timeout=120)
    killed: list[int] = []

    def progress(fraction, message):
        if message.startswith(phase) and not killed:
            _kill_a_busy_worker(client, killed)

    dist = render(every_pass_scene(), SETTINGS, client=client, progress=progress, spectral_film=True)
    assert len(killed) == 1
    assert_identical(local, dist)
    t0 = time.perf_counter()  # it really died, and its nanny replaced it
    while time.perf_counter() - t0 < 120:
        pids = client.run(os.getpid).values()
        if len(pids) == 2 and killed[0] not in pids:
            break
        time.sleep(0.2)
    assert len(pids) == 2 and killed[0] not in pids


@pytest.mark.slow
def test_cancel_stops_the_render_and_its_tasks(client):
    client.wait_for_workers(1, timeout=120)
    seen = []

    def progress(fraction, message):
        seen.append(message)

    settings = RenderSettings(samples=64, round_samples=2, light_paths=0, seed=1, tile_size=8)
    t0 = time.perf_counter()
    r = render(every_pass_scene(64, 48), settings, client=client, progress=progress,
               should_cancel=lambda: any(m.startswith("eye pass") for m in seen))
    assert r.cancelled and r.samples < 64
    assert r.stats["eye_tasks"] < 48 * 32  # most of the 1536 tile tasks were never submitted
    assert time.perf_counter() - t0 < 30
    assert _wait_until_forgotten(client) == []  # pending tasks cancelled, results released
    # cancelled during the light pass: a black, cancelled image, as locally
    seen.clear()
    r = render(every_pass_scene(), SETTINGS, client=client, progress=progress,
               should_cancel=lambda: any(m.startswith("light pass") for m in seen))
    assert r.cancelled and r.samples == 0 and float(np.abs(r.rgb).max()) == 0.0
    assert 0 < r.stats["light_paths"] < 150_000
    assert _wait_until_forgotten(client) == []


def test_the_wire_names_none_of_our_modules_and_round_trips():
    """Workers unpickle plain data and find the task functions by their stable module path, so
    a client that imported the core under another name (Blender's bl_ext...) still works."""
    scene = every_pass_scene()
    wire = to_wire((scene, SETTINGS))
    assert b"opal_diffraction" not in pickle.dumps(wire, protocol=5)
    back_scene, back_settings = from_wire(wire)
    assert back_settings == SETTINGS
    # field by field: Python 3.13's dataclass __eq__ compares fields with == one by one (no tuple
    # identity shortcut), which is ambiguous for the camera's matrix array
    for f in dataclasses.fields(Camera):
        assert np.array_equal(getattr(back_scene.camera, f.name), getattr(scene.camera, f.name)), f.name
    np.testing.assert_array_equal(back_scene.vertices, scene.vertices)
    np.testing.assert_array_equal(back_scene.materials.period, scene.materials.period)
    assert b"opal_diffraction.core.render.distributed" in pickle.dumps(TILE_TASK)
    assert pickle.loads(pickle.dumps(TILE_TASK)).__name__ == "tile_task"
    with pytest.raises(TypeError, match="cannot be sent"):
        to_wire(prepare(scene, SETTINGS))


def test_light_maps_travel_as_their_rows_that_hold_flux_exactly():
    prepared = prepare(every_pass_scene(), SETTINGS)
    light = run_light_pass(prepared, plan=plan_render(prepared))
    m = light.caustics
    m.flux[0, 0] = -0.0  # a negative zero is bits too
    packed = pack_map(m)
    assert len(packed["rows"]) < len(m.flux)
    back = unpack_map(pickle.loads(pickle.dumps(packed, protocol=5)))
    assert back.flux.tobytes() == m.flux.tobytes()
    np.testing.assert_array_equal(back.layout.offset, m.layout.offset)
    # the grating records are sparse lobes (grating_records.GratingRecords): all of them travel
    rec = light.grating_records
    rec.flux[0, 0] = -0.0
    back = unpack_map(pickle.loads(pickle.dumps(pack_map(rec), protocol=5)))
    for name in ("keys", "flux", "direction", "count"):
        assert getattr(back, name).tobytes() == getattr(rec, name).tobytes(), name
    np.testing.assert_array_equal(back.layout.offset, rec.layout.offset)
    assert pack_map(None) is None and unpack_map(None) is None


def test_importing_the_core_never_imports_dask():
    code = ("import sys, pkgutil, importlib, opal_diffraction.core as c\n"
            "for m in pkgutil.walk_packages(c.__path__, 'opal_diffraction.core.'):\n"
            "    importlib.import_module(m.name)\n"
            "import opal_diffraction.cli\n"
            "bad = [m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')]\n"
            "assert not bad, bad\n")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


def test_without_dask_a_scheduler_is_a_readable_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # as if dask were not installed
    with pytest.raises(ClusterError, match="needs dask: pip install -r requirements-dask.txt"):
        with connect("local:2"):
            pass


def test_scheduler_addresses_fail_with_a_readable_error():
    pytest.importorskip("distributed")
    with pytest.raises(ClusterError, match="local:N"):
        with connect("local:0"):
            pass
    with pytest.raises(ClusterError, match="cannot reach the Dask scheduler"):
        with connect("tcp://127.0.0.1:9", timeout=1):  # nothing listens there
            pass


@pytest.mark.slow
def test_cli_renders_the_same_exr_on_local_workers(tmp_path):
    pytest.importorskip("distributed")
    scene = tmp_path / "scene.npz"
    save_scene(every_pass_scene(24, 16), str(scene))
    common = [sys.executable, "-m", "opal_diffraction", "render", str(scene), "--spp", "2", "--light-paths",
              "40000", "--seed", "4", "-q"]
    subprocess.run(common + ["-o", str(tmp_path / "a.exr"), "--spectral-exr", str(tmp_path / "a_s.exr")],
                   check=True, timeout=300)
    out = subprocess.run(common + ["-o", str(tmp_path / "b.exr"), "--spectral-exr", str(tmp_path / "b_s.exr"),
                                   "--scheduler", "local:2"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "a.exr").read_bytes() == (tmp_path / "b.exr").read_bytes()
    assert (tmp_path / "a_s.exr").read_bytes() == (tmp_path / "b_s.exr").read_bytes()
    bad = subprocess.run(common + ["-o", str(tmp_path / "c.exr"), "--scheduler", "tcp://127.0.0.1"],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and bad.stderr.strip().startswith("error: cannot reach the Dask scheduler")


def test_the_dask_extra_is_the_requirements_pin_and_this_venv_runs_it():
    """pyproject.toml's extra "dask" and requirements-dask.txt (what ./setup.sh installs) agree."""
    import importlib.metadata as md
    import tomllib

    from packaging.requirements import Requirement

    from opal_diffraction._scripts import REPO_ROOT

    with open(os.path.join(REPO_ROOT, "pyproject.toml"), "rb") as f:
        extra = [Requirement(r) for r in tomllib.load(f)["project"]["optional-dependencies"]["dask"]]
    with open(os.path.join(REPO_ROOT, "requirements-dask.txt")) as f:
        pinned = [Requirement(line.strip()) for line in f if line.strip() and not line.startswith("#")]
    assert [(r.name, r.extras, str(r.specifier)) for r in extra] == [(r.name, r.extras, str(r.specifier))
                                                                     for r in pinned]
    (pin,) = pinned
    assert pin.name == "dask" and pin.extras == {"distributed"} and str(pin.specifier).startswith("==")
    version = str(pin.specifier)[2:]
    pytest.importorskip("distributed")
    assert md.version("dask") == md.version("distributed") == version

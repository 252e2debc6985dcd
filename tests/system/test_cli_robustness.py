"""The command line with bad input: every malformed file or argument is one ``error:`` line and
exit status 2 before any rendering; signals leave no temporary files and no traceback.

The malformed files are generated from one small valid scene (every array missing, of the wrong
dtype, of the wrong shape, holding NaN, a corrupted zip member, truncated files, files that are not
scenes) and run through ``cli.main`` in this process (fast); a few real subprocesses check the
signals.
"""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
import time
import zipfile
from contextlib import redirect_stderr
from dataclasses import fields

import numpy as np
import pytest

from opal_diffraction import cli
from opal_diffraction.core.scene import primitives
from opal_diffraction.core.scene.model import Camera, Lights, Materials, Scene
from opal_diffraction.core.scene.npz import save_scene

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
FAST = ["--spp", "1", "--light-paths", "0", "--wavelength-step", "50", "-q"]


def small_scene(pixels=4) -> Scene:
    """A valid scene with every table non-empty (so every column has rows to break)."""
    s = Scene(materials=Materials.from_list([
        {"kind": "DIFFUSE", "color": (0.5, 0.5, 0.5)},
        {"kind": "DIELECTRIC", "ior": 1.5, "dispersion": "ABBE", "abbe": 40.0, "grating": 1, "period": 1000.0,
         "slit_width": 500.0, "name": "glass"},
    ]))
    s.add_mesh(*primitives.quad((0, 0, 0), (6, 0, 0), (0, 6, 0)), material=0, tangent=(1, 0, 0), period=0.0)
    s.add_mesh(*primitives.box((0, 0, 0.5), (1, 1, 1)), material=1)
    s.lights = Lights.from_list([{"kind": "POINT", "position": (0, 0, 3), "power": 50.0},
                                 {"kind": "AREA_RECT", "position": (1, 0, 3), "power": 50.0, "size_u": 0.5}])
    s.camera = Camera.look_at((0, -4, 3), (0, 0, 0), width=pixels, height=pixels)
    s.world_color = np.array([0.1, 0.1, 0.1], np.float32)
    return s


def scene_arrays(s: Scene) -> dict:
    """The arrays Scene.save writes, by member name."""
    d = {"format_version": np.array(1), "vertices": s.vertices, "triangles": s.triangles,
         "tri_material": s.tri_material, "world_color": s.world_color, "tri_tangent": s.tri_tangent,
         "tri_period": s.tri_period}
    for f in fields(Materials):
        d["material_" + f.name] = getattr(s.materials, f.name)
    for f in fields(Lights):
        d["light_" + f.name] = getattr(s.lights, f.name)
    for f in fields(Camera):
        val = np.asarray(getattr(s.camera, f.name))
        if val.size or f.name not in ("motion", "shutter_table"):  # a still camera's are not written
            d["camera_" + f.name] = val
    return d


REQUIRED = {"format_version", "vertices", "triangles", "tri_material", "world_color", "camera_matrix"}
# missing these falls back to a default (an older file): a clean render, not an error
OPTIONAL = {"tri_tangent", "tri_period"} | {"material_" + f.name for f in fields(Materials) if f.name != "kind"} | {
    "camera_" + f.name for f in fields(Camera) if f.name != "matrix"} | {
    "light_radius", "light_angle", "light_soft_falloff", "light_camera_visible"}  # light columns newer than format 1 (core/scene/npz.py _LIGHT_OPTIONAL)


def malformed_files(folder) -> list[tuple[str, str, bool]]:
    """(name, path, must_fail) for every generated variant; must_fail False: exit 0 or 2 allowed."""
    base = scene_arrays(small_scene())
    out = []

    def save(name, arrays, must_fail=True, compressed=True):
        path = os.path.join(folder, name + ".npz")
        (np.savez_compressed if compressed else np.savez)(path, **arrays)
        out.append((name, path, must_fail))
        return path

    for key, arr in base.items():
        a = np.asarray(arr)
        # missing member
        rest = {k: v for k, v in base.items() if k != key}
        save(f"missing-{key}", rest, must_fail=key not in OPTIONAL)
        # wrong dtypes: strings, complex, booleans (a name column holds strings, a flag may be bool)
        if key not in ("material_name", "camera_kind", "camera_sensor_fit", "camera_panorama_type"):
            save(f"str-{key}", {**base, key: a.astype(str)})
            save(f"complex-{key}", {**base, key: a.astype(complex)})
            if key != "material_grating":
                save(f"bool-{key}", {**base, key: a.astype(bool)})
        else:
            save(f"number-{key}", {**base, key: np.zeros(a.shape, np.float64)})
        # wrong shape: an extra trailing axis (a (M,) column becomes (M, 2), (M, 3) becomes (M, 3, 2))
        save(f"shape-{key}", {**base, key: np.stack([a, a], axis=-1)})
        # fewer rows (or, for a scalar, an empty array)
        if a.ndim and len(a) > 1:
            save(f"rows-{key}", {**base, key: a[:-1]}, must_fail=key not in ("tri_tangent", "tri_period"))
        elif a.ndim == 0 and key not in ("camera_kind", "camera_sensor_fit", "camera_panorama_type"):
            save(f"empty-{key}", {**base, key: np.zeros(0, a.dtype)})
        # a NaN in a float column
        if a.dtype.kind == "f":
            b = a.astype(np.float64).copy()
            b.reshape(-1)[0] = np.nan
            save(f"nan-{key}", {**base, key: b})
            c = a.astype(np.float64).copy()
            c.reshape(-1)[-1] = 1e39  # finite in float64, inf in float32
            save(f"huge-{key}", {**base, key: c}, must_fail=key not in ("material_abbe",))
    # values that are valid numbers but impossible
    save("camera-1e9-pixels", {**base, "camera_width": np.array(100_000), "camera_height": np.array(10_000)})
    save("camera-zero-width", {**base, "camera_width": np.array(0)})
    save("light-power-1e41", {**base, "light_power": np.array([1e41, 1.0])})
    save("light-tiny-area", {**base, "light_size_u": np.array([1.0, 1e-30])})
    save("light-temperature-1K", {**base, "light_temperature": np.array([1.0, 0.0])})
    save("light-kind-9", {**base, "light_kind": np.array([9, 0], np.int32)})
    save("grating-rotation-inf", {**base, "material_rotation": np.array([0.0, np.inf], np.float32)})
    save("grating-slits-0", {**base, "material_slit_count": np.array([1000, 0], np.int32)})
    save("triangle-index-out", {**base, "triangles": base["triangles"] + 1000})
    save("material-index-out", {**base, "tri_material": base["tri_material"] + 5})
    save("vertices-1e39", {**base, "vertices": base["vertices"].astype(np.float64) * 1e39})
    save("format-newer", {**base, "format_version": np.array(99)})
    save("format-float", {**base, "format_version": np.array(1.5)})
    save("object-array", {**base, "vertices": base["vertices"].astype(object)}, compressed=False)
    # corrupted zip members: flip bytes inside each member's compressed data
    good = os.path.join(folder, "good.npz")
    np.savez_compressed(good, **base)
    with zipfile.ZipFile(good) as zf:
        infos = zf.infolist()
    raw = open(good, "rb").read()
    for info in infos:
        data_start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
        size = max(info.compress_size, 1)
        for where in (0.5,):
            b = bytearray(raw)
            i = data_start + int(size * where)
            for j in range(i, min(i + 4, data_start + size)):
                b[j] ^= 0xFF
            name = f"corrupt-{info.filename}"
            path = os.path.join(folder, name + ".npz")
            open(path, "wb").write(bytes(b))
            out.append((name, path, True))
    # truncated archives
    for frac in (0.0, 0.01, 0.1, 0.3, 0.5, 0.7, 0.9, 0.99):
        path = os.path.join(folder, f"truncated-{frac}.npz")
        open(path, "wb").write(raw[: int(len(raw) * frac)])
        out.append((f"truncated-{frac}", path, True))
    # files that are not scenes
    np.save(os.path.join(folder, "array.npy"), np.zeros(3))
    out.append(("npy", os.path.join(folder, "array.npy"), True))
    np.save(os.path.join(folder, "array-as.npz"), np.zeros(3))
    os.replace(os.path.join(folder, "array-as.npz.npy"), os.path.join(folder, "array-as.npz"))
    out.append(("npy-named-npz", os.path.join(folder, "array-as.npz"), True))
    for name, content in (("text", b"hello\n"), ("binary", os.urandom(512)), ("zip-header-only", b"PK\x03\x04"),
                          ("null-bytes", b"\0" * 100)):
        path = os.path.join(folder, name + ".npz")
        open(path, "wb").write(content)
        out.append((name, path, True))
    zpath = os.path.join(folder, "zip-of-text.npz")
    with zipfile.ZipFile(zpath, "w") as zf:
        zf.writestr("readme.txt", "not a scene")
    out.append(("zip-of-text", zpath, True))
    np.savez(os.path.join(folder, "other-arrays.npz"), a=np.zeros(3))
    out.append(("other-arrays", os.path.join(folder, "other-arrays.npz"), True))
    empty = os.path.join(folder, "empty.npz")
    open(empty, "wb").close()
    out.append(("empty", empty, True))
    os.mkdir(os.path.join(folder, "a-directory.npz"))
    out.append(("directory", os.path.join(folder, "a-directory.npz"), True))
    out.append(("missing-file", os.path.join(folder, "no-such-file.npz"), True))
    return out


def run_main(argv) -> tuple[int, str]:
    err = io.StringIO()
    with redirect_stderr(err):
        code = cli.main(argv)
    return code, err.getvalue()


def assert_clean_error(code, err, what):
    assert code == 2, f"{what}: exit {code}, stderr {err!r}"
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), f"{what}: {err!r}"
    assert "Traceback" not in err, f"{what}: {err!r}"


def tmp_files(folder):
    return [os.path.join(d, f) for d, _, files in os.walk(folder) for f in files if f.startswith(".tmp_")]


def test_malformed_scene_files_are_one_line_errors(tmp_path):
    files = tmp_path / "files"
    files.mkdir()
    cases = malformed_files(str(files))
    assert len(cases) >= 350, len(cases)
    outdir = tmp_path / "out"
    outdir.mkdir()
    results = {"error": 0, "rendered": 0}
    for name, path, must_fail in cases:
        out = outdir / f"{name}.exr"
        code, err = run_main(["render", path, "-o", str(out)] + FAST)
        assert "Traceback" not in err, f"{name}: {err}"
        if must_fail or code != 0:
            assert_clean_error(code, err, name)
            assert not out.exists(), f"{name}: wrote an image for a bad file"
            results["error"] += 1
        else:
            assert out.exists(), name
            results["rendered"] += 1
    assert not tmp_files(tmp_path)
    print(f"\nmalformed files: {len(cases)} variants, {results['error']} clean errors, {results['rendered']} rendered "
          f"(variants an older file may also have: a missing optional array)")
    assert results["error"] >= 360, results


def test_bad_arguments_and_output_paths_are_one_line_errors(tmp_path):
    scene = tmp_path / "scene.npz"
    save_scene(small_scene(), scene)
    out = str(tmp_path / "out.exr")
    (tmp_path / "a-dir.exr").mkdir()
    (tmp_path / "file").write_text("x")
    bad = {
        "png output": ["-o", str(tmp_path / "out.png")],
        "no extension": ["-o", str(tmp_path / "out")],
        "output is a directory": ["-o", str(tmp_path / "a-dir.exr")],
        "folder is a file": ["-o", str(tmp_path / "file" / "out.exr")],
        "output is the scene": ["-o", str(scene)],
        "spectral equals output": ["-o", out, "--spectral-exr", out],
        "spectral equals output via ..": ["-o", out, "--spectral-exr", str(tmp_path / "x" / ".." / "out.exr")],
        "spectral not exr": ["-o", out, "--spectral-exr", str(tmp_path / "s.png")],
        "spectral equals preview": ["-o", out, "--preview", str(tmp_path / "p.png"), "--spectral-exr",
                                    str(tmp_path / "p.png")],
        "preview equals output": ["-o", out, "--preview", out],
        "preview not png": ["-o", out, "--preview", str(tmp_path / "p.jpg")],
        "spp not a number": ["-o", out, "--spp", "x"],
        "spp zero": ["-o", out, "--spp", "0"],
        "negative seed": ["-o", out, "--seed", "-1"],
        "negative threads": ["-o", out, "--threads", "-1"],
        "unknown backend": ["-o", out, "--backend", "cuda"],
        "tiny wavelength step": ["-o", out, "--wavelength-step", "0.001"],
        "single wavelength": ["-o", out, "--wavelength-min", "500", "--wavelength-max", "501"],
        "wavelength nan": ["-o", out, "--wavelength-step", "nan"],
        "wavelength outside observer": ["-o", out, "--wavelength-min", "200"],
        "resolution zero": ["-o", out, "--resolution", "0", "4"],
        "resolution 1e9 pixels": ["-o", out, "--resolution", "50000", "20000"],
        "resolution one value": ["-o", out, "--resolution", "4"],
        "negative light paths": ["-o", out, "--light-paths", "-5"],
        "time limit nan": ["-o", out, "--time-limit", "nan"],
        "exposure inf": ["-o", out, "--exposure", "inf"],
        "unknown option": ["-o", out, "--frobnicate"],
        "dispersion sampling": ["-o", out, "--dispersion-sampling", "MAYBE"],
    }
    for what, extra in bad.items():
        code, err = run_main(["render", str(scene)] + FAST + extra)
        assert_clean_error(code, err, what)
    assert not os.path.exists(out) and not tmp_files(tmp_path)
    assert_clean_error(*run_main([]), "no command")
    assert_clean_error(*run_main(["render", str(scene)]), "no output")
    # a missing output folder is created, and removed again when the run fails
    code, err = run_main(["render", str(scene), "-o", str(tmp_path / "new" / "deep" / "o.exr"), "--spp", "0"])
    assert_clean_error(code, err, "bad spp with a new folder")
    assert not (tmp_path / "new").exists()
    code, err = run_main(["render", str(scene), "-o", str(tmp_path / "new" / "deep" / "o.exr")] + FAST)
    assert code == 0, err
    assert (tmp_path / "new" / "deep" / "o.exr").exists() and (tmp_path / "new" / "deep" / "o.png").exists()


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="needs a non-root POSIX user (root writes anywhere)")
def test_unwritable_folder_is_an_error_before_the_render(tmp_path):
    scene = tmp_path / "scene.npz"
    save_scene(small_scene(), scene)
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        code, err = run_main(["render", str(scene), "-o", str(ro / "out.exr")] + FAST)
        assert_clean_error(code, err, "read-only folder")
        assert "not writable" in err
    finally:
        ro.chmod(0o700)


# ------------------------------------------------------------------------------ subprocesses
def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("OPAL_DEBUG", None)
    return env


# Runs the CLI with the EXR writer slowed down: it writes the temporary file, says so on stderr
# ("WRITING <path>") and waits, so a test can signal the process in the middle of a write.
SLOW_WRITE = r"""
import sys, time
import OpenEXR
real = OpenEXR.File
class Slow:
    def __init__(self, *a, **k):
        self.f = real(*a, **k)
    def write(self, path):
        self.f.write(path)
        sys.stderr.write("WRITING " + path + "\n"); sys.stderr.flush()
        time.sleep(60)
OpenEXR.File = Slow
from opal_diffraction.cli import main
sys.exit(main(sys.argv[1:]))
"""


def _start(args, slow_write=False):
    cmd = [sys.executable, "-c", SLOW_WRITE] if slow_write else [sys.executable, "-m", "opal_diffraction"]
    return subprocess.Popen(cmd + args, cwd=ROOT, env=_env(), stderr=subprocess.PIPE, stdout=subprocess.PIPE)


def _read_some(proc, timeout) -> bytes:
    """What stderr has now (unbuffered reads of the pipe), waiting up to ``timeout``."""
    import select

    fd = proc.stderr.fileno()
    ready, _, _ = select.select([fd], [], [], timeout)
    return os.read(fd, 65536) if ready else b""


def _wait_for(proc, marker: bytes, timeout=120.0) -> bytes:
    """Read stderr until ``marker`` appears (the progress bar or the slow writer's line)."""
    seen = b""
    t0 = time.monotonic()
    while marker not in seen:
        if time.monotonic() - t0 > timeout:
            proc.kill()
            raise AssertionError(f"no {marker!r} after {timeout} s: {seen!r}")
        chunk = _read_some(proc, 0.1)
        if not chunk and proc.poll() is not None:
            raise AssertionError(f"exited {proc.returncode} before {marker!r}: {seen!r}")
        seen += chunk
    return seen


def _finish(proc, seen: bytes, timeout=120.0) -> tuple[int, str]:
    t0 = time.monotonic()
    while True:
        if time.monotonic() - t0 > timeout:
            proc.kill()
            raise AssertionError(f"still running {timeout} s after the signal: {seen!r}")
        chunk = _read_some(proc, 0.1)
        seen += chunk
        if not chunk and proc.poll() is not None:
            seen += _read_some(proc, 0.0)
            break
    proc.wait()
    return proc.returncode, seen.decode(errors="replace")


@pytest.fixture(scope="module")
def slow_scene(tmp_path_factory):
    """A scene whose render takes a few seconds (so a signal arrives during it)."""
    folder = tmp_path_factory.mktemp("signals")
    s = small_scene(pixels=160)
    path = folder / "scene.npz"
    save_scene(s, path)
    return path


SLOW_ARGS = ["--spp", "64", "--light-paths", "0", "--threads", "1", "--wavelength-step", "10"]


@pytest.mark.parametrize("sig, code, partial", [(signal.SIGINT, 130, False), (signal.SIGINT, 130, True),
                                               (signal.SIGTERM, 143, False)])
def test_signal_during_the_render(tmp_path, slow_scene, sig, code, partial):
    out = tmp_path / "out.exr"
    proc = _start(["render", str(slow_scene), "-o", str(out)] + SLOW_ARGS + (["--save-partial"] if partial else []))
    seen = _wait_for(proc, b"eye pass: round")
    proc.send_signal(sig)
    rc, err = _finish(proc, seen)
    assert rc == code, err
    assert "Traceback" not in err, err
    assert not tmp_files(tmp_path)
    assert out.exists() == partial, err
    if partial:
        from opal_diffraction.core.render.output import read_exr

        assert read_exr(out)["R"].shape == (160, 160)
        assert "partial image" in err


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_signal_during_the_write_leaves_no_temporary_file(tmp_path, slow_scene, sig, code):
    out = tmp_path / "out.exr"
    proc = _start(["render", str(slow_scene), "-o", str(out), "--resolution", "8", "8", "-q"] + SLOW_ARGS[:4],
                  slow_write=True)
    seen = _wait_for(proc, b"WRITING ")
    tmp = seen.split(b"WRITING ", 1)[1].split(b"\n", 1)[0].decode()
    assert os.path.basename(tmp).startswith(".tmp_") and os.path.exists(tmp)
    proc.send_signal(sig)
    rc, err = _finish(proc, seen)
    assert rc == code, err
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("WRITING")]
    assert len(lines) == 1, err
    assert not os.path.exists(tmp) and not tmp_files(tmp_path) and not out.exists()


def test_a_malformed_file_in_a_real_process(tmp_path):
    d = scene_arrays(small_scene())
    d["material_color"] = np.zeros((2, 2), np.float32)  # per-row shape wrong, row count right
    np.savez_compressed(tmp_path / "bad.npz", **d)
    p = subprocess.run([sys.executable, "-m", "opal_diffraction", "render", str(tmp_path / "bad.npz"), "-o",
                        str(tmp_path / "o.exr")], cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=120)
    assert_clean_error(p.returncode, p.stderr, "bad colour shape")
    assert "material table column 'color'" in p.stderr


@pytest.mark.parametrize("key", ["format_version", "material_kind", "camera_matrix", "camera_width", "vertices"])
def test_a_member_that_is_not_an_npy_array_is_an_input_error(tmp_path, key):
    """A zip member stored without the .npy format (NpzFile hands back its raw bytes): exit 2, one line."""
    path = tmp_path / "raw-member.npz"
    base = scene_arrays(small_scene())
    np.savez(path, **{k: v for k, v in base.items() if k != key})
    with zipfile.ZipFile(path, "a") as zf:
        zf.writestr(key, b"not an array")
    out = tmp_path / "out.exr"
    code, err = run_main(["render", str(path), "-o", str(out)] + FAST)
    assert_clean_error(code, err, key)
    assert not out.exists()


def test_ctrl_c_in_the_light_pass_with_save_partial_writes_nothing_and_says_so(tmp_path):
    """No pixel has a sample yet: a 'partial image' would be all black, so none is written."""
    from opal_diffraction._scripts import load_example

    scene = tmp_path / "prism.npz"
    save_scene(load_example("prism").build_scene(64, 40), scene)
    out = tmp_path / "out.exr"
    proc = _start(["render", str(scene), "-o", str(out), "--spp", "4", "--light-paths", "50000000",
                   "--threads", "1", "--save-partial"])
    seen = _wait_for(proc, b"light pass:")
    proc.send_signal(signal.SIGINT)
    rc, err = _finish(proc, seen)
    assert rc == 130, err
    assert "Traceback" not in err, err
    assert "before any pixel had a sample: nothing written" in err, err
    assert not out.exists() and not tmp_files(tmp_path)


def test_a_time_limit_that_runs_out_while_preparing_is_a_one_line_error(tmp_path):
    """A 330k-triangle sphere takes longer than 1 ms to prepare: exit 2, nothing written."""
    from opal_diffraction.core.scene import primitives

    s = small_scene()
    s.add_mesh(*primitives.icosphere((0, 0, 0.5), 0.3, 7), material=0)
    path = tmp_path / "big.npz"
    save_scene(s, path)
    out = tmp_path / "out.exr"
    p = subprocess.run([sys.executable, "-m", "opal_diffraction", "render", str(path), "-o", str(out),
                        "--time-limit", "0.001"], cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=300)
    assert_clean_error(p.returncode, p.stderr, "time limit while preparing")
    assert "time limit (0.001 s) ran out while preparing the scene" in p.stderr and "triangles" in p.stderr
    assert not out.exists() and not tmp_files(tmp_path)

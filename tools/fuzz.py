"""Fuzz the render's inputs at scale and count the outcomes (issue 27's "Must show").

Two sets:

- ``core N``: N cases drawn from tests/system/test_fuzz.py's generator (``mutated()``: random
  scenes and settings with NaN / inf / huge values, wrong shapes and dtypes, bad indices),
  rendered through ``core.render.frame.render``;
- ``cli``: tests/system/test_cli_robustness.py's malformed scene files (``malformed_files``) and
  the bad arguments below, run through ``cli.main``.

Every case runs in a worker process (a pool of one, so the fuzz takes one core) under a
per-case timeout; a worker that does not answer in time is killed and replaced (a hang). The
outcomes counted:

    ok          a finite, non-negative image and no warning (CLI: exit 0, no warning line)
    warning     the same with a warning (RenderResult.warnings; CLI: a 'warning:' line)
    error       a named input error: SceneError with a one-line message (CLI: exit 2, one 'error:' line)
    uncaught    any other exception (CLI: another exit status or a traceback)
    nonfinite   a success holding NaN / Inf or negative spectral radiance (CLI: NaN / Inf in the
                written EXR; its RGB may be negative, out of the sRGB gamut)
    hang        no answer within the timeout

    PYTHONPATH=. python tools/fuzz.py core 2000 --timeout 60 --seed 27 --report /tmp/fuzz_core.json
    PYTHONPATH=. python tools/fuzz.py cli --timeout 60 --report /tmp/fuzz_cli.json
"""

from __future__ import annotations

import argparse
import importlib.util
import io
import json
import multiprocessing as mp
import os
import sys
import tempfile
import time
import traceback
from collections import Counter
from contextlib import redirect_stderr

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
OUTCOMES = ("ok", "warning", "error", "uncaught", "nonfinite", "hang")


def _test_module(name: str):
    """tests/system/<name>.py as a module (the generators live with their tests)."""
    spec = importlib.util.spec_from_file_location(f"_fuzz_{name}", os.path.join(ROOT, "tests", "system", name + ".py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# ----------------------------------------------------------------------------- the worker side
def _core_case(payload) -> tuple[str, str]:
    import numpy as np

    from opal_diffraction.core.render.frame import render
    from opal_diffraction.core.scene.checks import SceneError
    from opal_diffraction.core.scene.validation import validate

    s, rs, _notes = payload
    try:
        res = render(s, rs, spectral_film=True)
    except SceneError as e:
        msg = str(e)
        if not msg or "\n" in msg or "Traceback" in msg:
            return "uncaught", f"unclean SceneError message {msg!r}"
        return "error", msg
    except BaseException as e:  # noqa: BLE001 - the point is to catch everything
        return "uncaught", f"{type(e).__name__}: {e}\n{traceback.format_exc()}"
    clean = validate(s).scene
    shape = (int(clean.camera.height), int(clean.camera.width), rs.grid().n)
    if res.spectral.shape != shape:
        return "uncaught", f"spectral shape {res.spectral.shape} != {shape}"
    arrays = [("spectral", res.spectral), ("rgb", res.rgb)] + list(res.passes.items())
    bad = [name for name, a in arrays if not np.isfinite(a).all()]
    if bad:
        return "nonfinite", f"non-finite output in {bad}; warnings {res.warnings}"
    if (res.spectral < 0).any():
        return "nonfinite", f"negative spectral radiance (min {res.spectral.min()})"
    return ("warning", "; ".join(res.warnings)) if res.warnings else ("ok", "")


def _cli_case(payload) -> tuple[str, str]:
    import numpy as np

    from opal_diffraction import cli
    from opal_diffraction.core.render.output import read_exr

    argv, out = payload
    err = io.StringIO()
    try:
        with redirect_stderr(err):
            code = cli.main(argv)
    except BaseException as e:  # noqa: BLE001
        return "uncaught", f"{type(e).__name__}: {e}\n{traceback.format_exc()}"
    text = err.getvalue()
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if "Traceback" in text:
        return "uncaught", text[-2000:]
    if code == 2:
        ok = len(lines) >= 1 and lines[-1].startswith("error: ")
        return ("error", lines[-1]) if ok else ("uncaught", f"exit 2 without one error line: {text!r}")
    if code != 0:
        return "uncaught", f"exit {code}: {text[-2000:]!r}"
    if out and os.path.exists(out):
        try:
            # RGB may be negative (a spectrum outside the sRGB gamut); only NaN / Inf is wrong here
            bad = [k for k, a in read_exr(out).items() if not np.isfinite(a).all()]
        except Exception as e:  # noqa: BLE001
            return "uncaught", f"unreadable output: {e!r}"
        finally:
            os.remove(out)
        if bad:
            return "nonfinite", f"non-finite channels {bad}; {text!r}"
    warned = [ln for ln in lines if ln.startswith("warning")]
    return ("warning", "; ".join(warned)) if warned else ("ok", "")


def _worker(conn) -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from opal_diffraction.core.render.frame import compile_stage

    compile_stage("auto")  # the process's compile stage now, not inside the first case's timeout
    conn.send("ready")
    while True:
        job = conn.recv()
        if job is None:
            return
        kind, payload = job
        conn.send((_core_case if kind == "core" else _cli_case)(payload))


class OneWorker:
    """A pool of one worker process with a per-case timeout: a case that runs past it is a hang
    (the worker is killed and a new one started)."""

    def __init__(self, timeout: float):
        self.timeout = timeout
        self.ctx = mp.get_context("spawn")
        self.proc = self.conn = None

    def _start(self):
        self.conn, child = self.ctx.Pipe()
        self.proc = self.ctx.Process(target=_worker, args=(child,), daemon=True)
        self.proc.start()
        if not self.conn.poll(600) or self.conn.recv() != "ready":
            raise RuntimeError("the fuzz worker did not start")

    def run(self, kind, payload) -> tuple[str, str, float]:
        if self.proc is None or not self.proc.is_alive():
            self._start()
        t0 = time.perf_counter()
        try:
            self.conn.send((kind, payload))
        except Exception as e:  # noqa: BLE001 - a case that cannot be pickled
            return "uncaught", f"case not sendable: {e!r}", 0.0
        if self.conn.poll(self.timeout):
            try:
                outcome, text = self.conn.recv()
            except EOFError:  # the worker died (a crash in native code)
                self.proc.join()
                outcome, text = "uncaught", f"worker died (exit {self.proc.exitcode})"
                self.proc = None
            return outcome, text, time.perf_counter() - t0
        self.proc.kill()  # a hang
        self.proc.join()
        self.proc = None
        return "hang", f"no answer after {self.timeout:g} s", time.perf_counter() - t0

    def close(self):
        if self.proc is not None and self.proc.is_alive():
            self.conn.send(None)
            self.proc.join(10)


# ----------------------------------------------------------------------------- the cases
def core_cases(n: int, seed: int):
    """``n`` cases of test_fuzz's generator, reproducibly from ``seed``."""
    from hypothesis import HealthCheck, given, seed as hseed, settings

    fz = _test_module("test_fuzz")
    out = []

    @hseed(seed)
    @settings(max_examples=n, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(case=fz.mutated())
    def collect(case):
        out.append(case)

    collect()
    return out, fz._scene_summary


def cli_cases(folder: str):
    """(name, argv, output) of the malformed files and the bad arguments."""
    cr = _test_module("test_cli_robustness")
    from opal_diffraction.core.scene.npz import save_scene

    cases = []
    for name, path, _must_fail in cr.malformed_files(os.path.join(folder, "files")):
        out = os.path.join(folder, "out", name + ".exr")
        cases.append((f"file {name}", ["render", path, "-o", out] + cr.FAST, out))
    scene = os.path.join(folder, "scene.npz")
    save_scene(cr.small_scene(), scene)
    out = os.path.join(folder, "out", "args.exr")
    bad_args = [
        ["--spp", "x"], ["--spp", "0"], ["--spp", "-3"], ["--spp", "1e9"], ["--seed", "-1"], ["--seed", "2e40"],
        ["--threads", "-1"], ["--threads", "100000"], ["--backend", "cuda"], ["--wavelength-step", "0.001"],
        ["--wavelength-step", "0.1174"], ["--wavelength-step", "nan"], ["--wavelength-step", "-5"],
        ["--wavelength-step", "1e9"], ["--wavelength-min", "500", "--wavelength-max", "501"],
        ["--wavelength-min", "200"], ["--wavelength-min", "700", "--wavelength-max", "400"],
        ["--resolution", "0", "4"], ["--resolution", "50000", "20000"], ["--resolution", "4"],
        ["--resolution", "-4", "4"], ["--resolution", "x", "y"], ["--light-paths", "-5"], ["--light-paths", "1e30"],
        ["--time-limit", "nan"], ["--time-limit", "-1"], ["--time-limit", "inf"], ["--time-limit", "0.001"],
        ["--exposure", "inf"], ["--exposure", "-1e308"], ["--exposure", "nan"], ["--frobnicate"],
        ["--dispersion-sampling", "MAYBE"], ["--spectral-exr", out], ["--preview", out],
        ["--preview", os.path.join(folder, "p.jpg")], ["--spectral-exr", os.path.join(folder, "s.png")],
    ]
    for extra in bad_args:
        a = ["render", scene, "-o", out] + cr.FAST
        # later options win in argparse: the bad value replaces FAST's good one
        cases.append(("args " + " ".join(extra), a + extra, out))
    for o in ("out.png", "out", "a-dir.exr", os.path.join("file", "out.exr")):
        cases.append((f"output {o}", ["render", scene, "-o", os.path.join(folder, o)] + cr.FAST, None))
    os.makedirs(os.path.join(folder, "a-dir.exr"), exist_ok=True)
    open(os.path.join(folder, "file"), "w").write("x")
    cases.append(("no command", [], None))
    cases.append(("no output", ["render", scene], None))
    return cases


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("set", choices=("core", "cli"))
    ap.add_argument("n", nargs="?", type=int, default=2000, help="core cases (default 2000)")
    ap.add_argument("--seed", type=int, default=27)
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds per case (a hang past it)")
    ap.add_argument("--report", default="", help="write the counts and the failing cases as JSON here")
    args = ap.parse_args(argv)
    counts: Counter = Counter()
    failures, slowest = [], 0.0
    pool = OneWorker(args.timeout)
    t0 = time.perf_counter()
    try:
        if args.set == "core":
            cases, summary = core_cases(args.n, args.seed)
            jobs = [(f"core {i}", ("core", c), c) for i, c in enumerate(cases)]
        else:
            tmp = tempfile.mkdtemp(prefix="opal_fuzz_cli_")
            os.makedirs(os.path.join(tmp, "files"))
            os.makedirs(os.path.join(tmp, "out"))
            jobs = [(name, ("cli", (a, o)), a) for name, a, o in cli_cases(tmp)]
            summary = None
        for i, (name, (kind, payload), case) in enumerate(jobs):
            outcome, text, dt = pool.run(kind, payload)
            slowest = max(slowest, dt)
            counts[outcome] += 1
            if outcome in ("uncaught", "nonfinite", "hang"):
                what = summary(*case) if summary is not None else " ".join(case)
                failures.append({"case": name, "outcome": outcome, "text": text, "input": what})
                print(f"{name}: {outcome}: {text.splitlines()[0] if text else ''}", file=sys.stderr, flush=True)
            if (i + 1) % 100 == 0:
                print(f"{i + 1}/{len(jobs)} {dict(counts)}", file=sys.stderr, flush=True)
    finally:
        pool.close()
    result = {"set": args.set, "cases": sum(counts.values()), **{k: counts.get(k, 0) for k in OUTCOMES},
              "slowest_s": round(slowest, 2), "seconds": round(time.perf_counter() - t0, 1)}
    print(json.dumps(result))
    if args.report:
        with open(args.report, "w") as f:
            json.dump({"summary": result, "failures": failures}, f, indent=1)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())

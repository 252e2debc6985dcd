"""The shipped opal presets (opal_diffraction/presets/opal/*.py), written from one table.

Each preset is a Blender preset file (``opal.<property> = value`` lines, blender/opal_presets.py)
whose header states its physics: the spheres' diameter D_s and spread, the void index, and what
follows from them, n_eff = sqrt(0.74 n_s^2 + 0.26 n_void^2) and the Bragg colour at normal
incidence lambda = 2 d111 n_eff for D_s +- spread (core/opal/bragg.py, docs/physics.md section
5.2). The table below is the one place those numbers are written; this tool writes the files
from it and checks that the shipped ones are what it writes (tests/opal/test_opal_presets.py runs the
check; docs/opal.md's preset table shows the same rows).

    python tools/opal_presets.py write    # rewrite opal_diffraction/presets/opal/*.py
    python tools/opal_presets.py check    # exit 1 if a shipped file differs from the table
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass

from opal_diffraction._scripts import REPO_ROOT
from opal_diffraction.core.opal.bragg import bragg_wavelength, effective_index

FOLDER = os.path.join(REPO_ROOT, "opal_diffraction", "presets", "opal")
N_SILICA = 1.45  # every preset's spheres (and the body's IOR)


@dataclass(frozen=True)
class BraggPreset:
    """An FCC opal (lattice BRAGG): spheres, voids, ordered layers, volume domains and the body."""

    name: str
    what: str               # the header's description, in parentheses after "<name> opal preset"
    sphere_diameter: float  # nm
    diameter_spread: float  # nm
    void_ior: float
    void: str               # what fills the voids (water, silica cement, air)
    layers: int
    mosaic_spread: float    # deg
    domain_count: int
    domain_size_spread: float
    domain_axis_spread: float  # deg: the (111) normals within this of the object's Z axis
    body_color: tuple[float, float, float]
    body_roughness: float
    body_transmission: float = 0.0


BRAGG_PRESETS = (
    BraggPreset("Black", "black opal: a dark potch body under the play of colour, the most saturated flashes",
                245.0, 45.0, 1.33, "water", 60, 6.0, 800, 0.6, 35.0, (0.008, 0.008, 0.01), 0.03),
    BraggPreset("Boulder", "boulder opal: a thin seam on brown ironstone, silica-filled voids (low contrast), "
                "planes parallel to the seam",
                225.0, 30.0, 1.4, "silica cement", 30, 6.0, 400, 0.5, 15.0, (0.06, 0.035, 0.02), 0.1),
    BraggPreset("Crystal", "crystal opal: a clear body, the flashes seen through the stone",
                245.0, 45.0, 1.33, "water", 60, 6.0, 800, 0.6, 35.0, (1.0, 1.0, 1.0), 0.0, 1.0),
    BraggPreset("Harlequin", "harlequin: few large angular domains of well-ordered spheres on a dark body",
                245.0, 50.0, 1.33, "water", 80, 4.0, 60, 0.3, 30.0, (0.008, 0.008, 0.01), 0.03),
    BraggPreset("Pinfire", "pinfire: many small domains, pin-point flashes, on a dark grey body",
                240.0, 45.0, 1.33, "water", 30, 8.0, 5000, 0.8, 40.0, (0.03, 0.03, 0.035), 0.05),
    BraggPreset("White", "white (light) opal: a milky body (diffuse base, the scattering approximated) under "
                "the flashes",
                240.0, 45.0, 1.33, "water", 30, 8.0, 800, 0.6, 40.0, (0.55, 0.56, 0.58), 0.1, 0.3),
)

#: The source paper's surface-grating opal (Kobayashi & Kawai; docs/physics.md section 5.1).
PAPER_MODEL = ("Paper_Model", """\
# The source paper's opal (Kobayashi & Kawai; docs/physics.md section 5.1): a surface grating, every
# triangle one grating of parallel slits, all oriented consistently (the object's X axis projected onto
# each face), one period of 550 nm (100 coherent slits, 2 um long), on a dark body. Not a physical opal:
# colour moves to the red away from the mirror direction.
""", [("grating", True), ("grating_type", "REFLECTION"), ("lattice", "LINES"), ("grating_direction", "ATTRIBUTE"),
      ("rotation", 0.0), ("period", 550.0), ("slit_width", 275.0), ("slit_count", 100), ("coherence_length", 2.0),
      ("domain_count", 1), ("body_color", [0.12, 0.12, 0.13]), ("body_roughness", 0.3), ("body_transmission", 0.0),
      ("node_ior", N_SILICA), ("dispersion", "NONE")])


def _value(v) -> str:
    """A property value as the shipped files write it (Blender's preset files use repr, 'quoted')."""
    return f"'{v}'" if isinstance(v, str) else repr(v)


def _file(header: str, values) -> str:
    body = "".join(f"opal.{k} = {_value(v)}\n" for k, v in values)
    return f"{header}import bpy\nopal = bpy.context.material.opal\n\n{body}"


def bragg_text(p: BraggPreset) -> str:
    """The preset file of ``p``: its header's physics computed from the table row."""
    n_eff = effective_index(N_SILICA, p.void_ior)
    lo, hi = (float(bragg_wavelength(p.sphere_diameter + k * p.diameter_spread, 0.0, N_SILICA, p.void_ior))
              for k in (-1, 1))
    header = (f"# {p.name} opal preset ({p.what}).\n"
              f"# Spheres D_s = {p.sphere_diameter:g} +- {p.diameter_spread:g} nm of silica (n_s {N_SILICA:g}), "
              f"voids n_void {p.void_ior:g} ({p.void}):\n"
              f"# n_eff {n_eff:.4f}, Bragg colour at normal incidence {lo:.0f}-{hi:.0f} nm (lambda = 2 d111 n_eff,\n"
              f"# d111 = sqrt(2/3) D_s; docs/physics.md section 5.2); {p.layers} ordered layers, mosaic spread "
              f"{p.mosaic_spread:g} deg;\n"
              f"# {p.domain_count} volume domains, layered (111) normals within {p.domain_axis_spread:g} deg of the "
              f"object's Z axis.\n")
    values = [("grating", True), ("grating_type", "REFLECTION"), ("lattice", "BRAGG"),
              ("grating_direction", "ATTRIBUTE"), ("rotation", 0.0), ("period", 550.0), ("slit_width", 275.0),
              ("sphere_diameter", p.sphere_diameter), ("sphere_ior", N_SILICA), ("void_ior", p.void_ior),
              ("layers", p.layers), ("mosaic_spread", p.mosaic_spread), ("domain_count", p.domain_count),
              ("domain_size_spread", p.domain_size_spread), ("domain_orientation", "LAYERED"),
              ("domain_axis_spread", p.domain_axis_spread), ("diameter_spread", p.diameter_spread),
              ("body_color", list(p.body_color)), ("body_roughness", p.body_roughness),
              ("body_transmission", p.body_transmission), ("node_ior", N_SILICA), ("dispersion", "NONE")]
    return _file(header, values)


def preset_files() -> dict[str, str]:
    """{file name: text} of every shipped opal preset, from the table."""
    out = {f"{p.name}.py": bragg_text(p) for p in BRAGG_PRESETS}
    name, header, values = PAPER_MODEL
    out[f"{name}.py"] = _file(header, values)
    return out


def differences(folder: str = FOLDER) -> list[str]:
    """The preset files in ``folder`` that are not what the table writes (missing, extra or changed)."""
    want = preset_files()
    have = {f for f in os.listdir(folder) if f.endswith(".py")}
    bad = [f"{f}: not in the table" for f in sorted(have - set(want))]
    for f, text in sorted(want.items()):
        path = os.path.join(folder, f)
        if not os.path.exists(path):
            bad.append(f"{f}: missing")
        else:
            with open(path, encoding="utf-8") as fh:
                if fh.read() != text:
                    bad.append(f"{f}: differs from the table")
    return bad


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=["write", "check"])
    args = ap.parse_args(argv)
    if args.mode == "write":
        for f, text in preset_files().items():
            with open(os.path.join(FOLDER, f), "w", encoding="utf-8") as fh:
                fh.write(text)
        return 0
    bad = differences()
    for line in bad:
        print(line, file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())

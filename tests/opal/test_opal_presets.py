"""The shipped opal presets are what tools/opal_presets.py writes from its one table, and their
headers' physics (n_eff, the Bragg colour range) follows from the table's numbers
(core/opal/bragg.py, docs/physics.md section 5.2)."""

import dataclasses
import os

from opal_diffraction._scripts import load_script

tool = load_script("tools/opal_presets.py")


def test_the_shipped_files_are_the_table():
    assert tool.differences() == []
    assert len(tool.preset_files()) == len(os.listdir(tool.FOLDER)) == 7


def test_a_changed_row_or_file_is_reported(tmp_path):
    """The check is not vacuous: a file edited by hand, an extra file and a missing one are found."""
    for name, text in tool.preset_files().items():
        (tmp_path / name).write_text(text, encoding="utf-8")
    assert tool.differences(str(tmp_path)) == []
    black = (tmp_path / "Black.py").read_text(encoding="utf-8")
    (tmp_path / "Black.py").write_text(black.replace("opal.layers = 60", "opal.layers = 61"), encoding="utf-8")
    (tmp_path / "Opal_2.py").write_text(black, encoding="utf-8")
    (tmp_path / "Pinfire.py").unlink()
    assert tool.differences(str(tmp_path)) == ["Opal_2.py: not in the table", "Black.py: differs from the table",
                                               "Pinfire.py: missing"]


def test_the_header_states_the_bragg_range_of_the_row():
    """Black: D_s 245 +- 45 nm in water, n_eff = sqrt(0.74 1.45^2 + 0.26 1.33^2) = 1.4198, lambda =
    2 sqrt(2/3) D_s n_eff = 464-672 nm (docs/opal.md's table); another diameter moves the stated
    range (250 +- 45: 475-684 nm)."""
    black = next(p for p in tool.BRAGG_PRESETS if p.name == "Black")
    text = tool.bragg_text(black)
    assert "n_eff 1.4198, Bragg colour at normal incidence 464-672 nm" in text
    assert "n_eff 1.4198, Bragg colour at normal incidence 475-684 nm" in tool.bragg_text(
        dataclasses.replace(black, sphere_diameter=250.0))

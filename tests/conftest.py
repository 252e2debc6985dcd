"""Shared pytest set-up. Nothing to do here: ./setup.sh installs the project editable, so the tests
import opal_diffraction as installed; the example scripts load through
opal_diffraction._scripts.load_example; pytest's configuration (test paths, markers) is in
pyproject.toml."""

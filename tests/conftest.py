"""Shared pytest set-up. Nothing to do here: ./setup.sh installs the project editable, so the tests
import opal_diffraction as installed; the example scripts load through
opal_diffraction._scripts.load_example; pytest's configuration (test paths, markers, and the
``pythonpath`` that lets a test in any room folder import the helpers beside this file) is in
pyproject.toml."""

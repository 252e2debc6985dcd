"""Shared pytest set-up. ./setup.sh installs the project editable, so the tests import
opal_diffraction as installed; the example scripts load through
opal_diffraction._scripts.load_example; pytest's configuration (test paths, markers, and the
``pythonpath`` that lets a test in any room folder import the helpers beside this file) is in
pyproject.toml.

With OPAL_KERNELS=numpy (the NumPy reference forced for the whole process, core/util/jit.py;
.ci/run runs the quick suite so) the tests of the compiled kernels themselves are skipped: they
compare each kernel with the reference, which they could not reach. Every other test then runs
on the reference."""

import os

import pytest

from opal_diffraction.core.util import jit

#: test files of the compiled kernels and of the compile stage (by name)
KERNEL_TEST_FILES = ("kernel", "compile_stage")


def pytest_collection_modifyitems(config, items):
    if os.environ.get(jit.KERNELS_ENV, "").strip().lower() != "numpy":
        return
    skip = pytest.mark.skip(reason=f"{jit.KERNELS_ENV}=numpy: the NumPy reference is forced, no kernel to test")
    for item in items:
        if any(word in os.path.basename(str(item.fspath)) for word in KERNEL_TEST_FILES):
            item.add_marker(skip)

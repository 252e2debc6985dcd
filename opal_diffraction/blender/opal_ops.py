"""The opal tools under their former module name: everything is in :mod:`.opal` (attributes,
operators, ui); this module re-exports it, so scripts that import ``opal_ops`` keep working."""

from __future__ import annotations

from .opal import *  # noqa: F401,F403
from .opal import __all__, classes, register, unregister  # noqa: F401
from .opal.ui import _menu_add  # noqa: F401

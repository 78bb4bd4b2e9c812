"""The compiled core: the planar leg's dynamics, contact and time stepping in C.

``kernels`` is the extension module built from ``module.c`` (and the files it includes: ``robot.h`` the
structs, ``dynamics.c``, ``contact.c``, ``integrate.c``, ``hybrid.c``) by the package's build backend at
install. Nothing is compiled at run time. Its functions take numpy arrays and loop over robots in C with
the GIL released; the public API (``leg_env.physics.dynamics``, ``leg_env.physics.contact``, ``leg_env.physics.integrate``,
``leg_env.physics.hybrid``) shapes and validates the arrays around them, and ``leg_env.physics.layout`` holds the numpy
dtypes of the C structs, checked against the compiled layout at import.
"""

from . import kernels

__all__ = ["kernels"]

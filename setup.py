"""The compiled core: one C extension, ``leg_env._core.kernels``, built by setuptools at install.

A C compiler and the Python headers are all it needs. The flags keep the arithmetic IEEE-exact and
the same on every machine: no fast-math, no contraction of multiply-adds into FMAs (which would change
the last bits from one CPU to another), and no ``-march=native`` (a wheel runs on any CPU of its
platform).
"""

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

CORE = "leg_env/_core"
HEADERS = [f"{CORE}/{name}" for name in ("structs.def", "fields.h", "robot.h", "env.h", "dynamics.c", "contact.c", "integrate.c",
                                        "hybrid.c", "tangent.c", "env.c", "tasks.c", "draws.c", "hopper.c", "plan.c", "calls.c", "objects.c")]

FLAGS = {
    "unix": ["-O3", "-std=c99", "-ffp-contract=off", "-fno-fast-math", "-fno-strict-aliasing", "-Wall", "-Wno-unused-function"],
    "msvc": ["/O2", "/fp:precise"],
}


class BuildExt(build_ext):
    """``build_ext`` with the core's compiler flags for the compiler in use."""

    def build_extensions(self):
        flags = FLAGS.get(self.compiler.compiler_type, FLAGS["unix"])
        for ext in self.extensions:
            ext.extra_compile_args = list(flags)
        super().build_extensions()


setup(
    ext_modules=[Extension("leg_env._core.kernels", sources=[f"{CORE}/module.c"], depends=HEADERS)],
    cmdclass={"build_ext": BuildExt},
)

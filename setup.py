"""The compiled kernel and its build: everything else about the package is in pyproject.toml.

``src/roarmctl/_kernel.c`` (the library's FK, Jacobian and inverse dynamics and the state checker; docs/design.md
"One compiled FK, Jacobian and inverse dynamics" and "How the collision check is fast") uses only CPython's
limited API of 3.11, so ``pip wheel .`` builds one abi3 wheel for 3.11 and later. ``-fno-fast-math
-ffp-contract=off``: no FMA contraction, the same sums on every machine. Without a C compiler or the Python
headers the install stops with one line saying what to install.
"""

import os
import shutil
import sysconfig

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext
from setuptools.errors import CCompilerError, CompileError, ExecError, PlatformError

HINT = ("roarmctl's compiled kernel (src/roarmctl/_kernel.c) needs a C compiler and the Python headers: "
        "on Debian/Ubuntu 'sudo apt-get install gcc python3-dev', on Fedora 'sudo dnf install gcc python3-devel', "
        "on macOS 'xcode-select --install'; or install a prebuilt roarmctl wheel")


class BuildExt(build_ext):
    """``build_ext`` that checks for the compiler and ``Python.h`` first and turns a failed build into one line."""

    def run(self) -> None:
        """Build the extensions, or stop with HINT naming what is missing."""
        headers = os.path.join(sysconfig.get_paths()["include"], "Python.h")
        compiler = (os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc").split()[0]
        missing = [what for what, ok in (("a C compiler ('" + compiler + "')", shutil.which(compiler)),
                                         ("the Python headers (" + headers + ")", os.path.exists(headers))) if not ok]
        if missing:
            raise PlatformError(f"missing {' and '.join(missing)}. {HINT}")
        try:
            super().run()
        except (CCompilerError, CompileError, ExecError) as exc:
            raise PlatformError(f"building the kernel failed ({exc}). {HINT}") from None


KERNEL = Extension("roarmctl._kernel", sources=["src/roarmctl/_kernel.c", "src/roarmctl/_kernel_jerk.c"], py_limited_api=True,
                   define_macros=[("Py_LIMITED_API", "0x030B0000")],
                   extra_compile_args=["-O3", "-fno-fast-math", "-ffp-contract=off"])

setup(ext_modules=[KERNEL], cmdclass={"build_ext": BuildExt}, options={"bdist_wheel": {"py_limited_api": "cp311"}})

"""Builds paircast's extension with CMake (the same python/CMakeLists.txt as the main build) and
installs it with the pure-Python package. Offline: uses the system's CMake, compilers and
libraries (scripts/setup.sh installs them). CMAKE_ARGS adds CMake options, PAIRCAST_JOBS sets the
compile jobs."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = Path(__file__).resolve().parent


class CMakeExtension(Extension):
    def __init__(self, name):
        super().__init__(name, sources=[])


class CMakeBuild(build_ext):
    def build_extension(self, ext):
        build_dir = Path(self.build_temp).resolve() / "cmake"
        out_dir = build_dir / "python" / "paircast"
        configure = [
            "cmake", "-S", str(ROOT), "-B", str(build_dir), "-DCMAKE_BUILD_TYPE=Release",
            "-DPAIRCAST_WITH_TORCH=OFF", "-DPAIRCAST_BUILD_TESTS=OFF",
            "-DPAIRCAST_BUILD_BENCH=OFF", f"-DPython_EXECUTABLE={sys.executable}",
            f"-DPAIRCAST_PYTHON_OUTPUT_DIR={out_dir}",
        ]
        if shutil.which("ninja"):
            configure += ["-G", "Ninja"]
        configure += os.environ.get("CMAKE_ARGS", "").split()
        subprocess.run(configure, check=True)
        jobs = os.environ.get("PAIRCAST_JOBS", str(os.cpu_count() or 1))
        subprocess.run(["cmake", "--build", str(build_dir), "--target", "_paircast", "-j", jobs],
                       check=True)
        built = [p for p in out_dir.glob("_paircast*.so")]
        if not built:
            sys.exit(f"paircast: CMake built no extension in {out_dir} (is pybind11-dev installed?)")
        target = Path(self.get_ext_fullpath(ext.name))
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(built[0], target)


# build/ is CMake's; setuptools works in build/pip.
setup(ext_modules=[CMakeExtension("paircast._paircast")], cmdclass={"build_ext": CMakeBuild},
      options={"build": {"build_base": "build/pip"}})

"""The build behind pyproject.toml: the extension rayforge._rayforge and
librayforge, built by the project's CMake (the library and the module only:
no CLI, no tests) and placed in the package, where the module finds the
library next to itself ($ORIGIN). Environment:
  RAYFORGE_CMAKE_ARGS="-DRAYFORGE_ENABLE_CUDA=OFF ..."  more CMake options;
  RAYFORGE_JOBS=N                                         parallel compile jobs (default: all cores);
  RAYFORGE_BUILD_BASE=folder                              setuptools' build folder (default build-python);
  RAYFORGE_BUILD_DIR=build                                package an existing, built CMake build folder
                                                          (its module and library, installed into a staging
                                                          prefix) instead of compiling again: what the
                                                          install test does with the tree it has built."""

import os
import pathlib
import re
import shlex
import shutil
import subprocess
import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = pathlib.Path(__file__).parent.resolve()


class CMakeExtension(Extension):
    def __init__(self, name):
        super().__init__(name, sources=[])


class CMakeBuild(build_ext):
    def build_extension(self, ext):
        stage = pathlib.Path(self.build_temp).resolve() / "stage"
        package_dir = pathlib.Path(self.get_ext_fullpath(ext.name)).resolve().parent
        prebuilt = os.environ.get("RAYFORGE_BUILD_DIR")
        build = pathlib.Path(prebuilt).resolve() if prebuilt else self.cmake_build()
        shutil.rmtree(stage, ignore_errors=True)
        subprocess.run(["cmake", "--install", str(build), "--prefix", str(stage)], check=True,
                       stdout=subprocess.DEVNULL)
        modules = list(stage.rglob("rayforge/_rayforge*.so"))
        libraries = [p for p in stage.rglob("librayforge.so.*") if re.fullmatch(r"librayforge\.so\.\d+", p.name)]
        if len(modules) != 1 or len(libraries) != 1:
            sys.exit(f"rayforge: {build} installs {len(modules)} modules and {len(libraries)} libraries, "
                     "expected one each (was it configured with the Python module ON and built?)")
        package_dir.mkdir(parents=True, exist_ok=True)
        # The library once, under its SONAME (what the module asks for): wheels hold no symlinks.
        shutil.copy2(libraries[0].resolve(), package_dir / libraries[0].name)
        for item in modules[0].parent.iterdir():  # the module and the package's Python files
            if item.is_file():
                shutil.copy2(item, package_dir / item.name)

    def cmake_build(self):
        """Configures and builds the library and the module only; returns the build folder."""
        build = pathlib.Path(self.build_temp).resolve() / "cmake"
        configure = [
            "cmake", "-S", str(ROOT), "-B", str(build),
            "-DCMAKE_BUILD_TYPE=Release",
            "-DRAYFORGE_BUILD_TESTS=OFF", "-DRAYFORGE_BUILD_BENCHMARKS=OFF", "-DRAYFORGE_BUILD_APPS=OFF",
            f"-DPython3_EXECUTABLE={sys.executable}",
        ] + shlex.split(os.environ.get("RAYFORGE_CMAKE_ARGS", ""))
        jobs = str(os.environ.get("RAYFORGE_JOBS", os.cpu_count() or 1))
        subprocess.run(configure, check=True)
        subprocess.run(["cmake", "--build", str(build), "--target", "_rayforge", "-j", jobs], check=True)
        return build

setup(
    ext_modules=[CMakeExtension("rayforge._rayforge")],
    cmdclass={"build_ext": CMakeBuild},
    # Not ./build: that is the project's CMake build folder (scripts/build.sh).
    options={"build": {"build_base": os.environ.get("RAYFORGE_BUILD_BASE", "build-python")}},
)

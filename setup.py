"""The build behind pyproject.toml: the extension rayforge._rayforge and
librayforge, built by the project's CMake (the library and the module only:
no CLI, no tests) and placed in the package, where the module finds the
library next to itself ($ORIGIN). CMake options can be added through the
environment: RAYFORGE_CMAKE_ARGS="-DRAYFORGE_ENABLE_CUDA=OFF"."""

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
        build = pathlib.Path(self.build_temp).resolve() / "cmake"
        stage = pathlib.Path(self.build_temp).resolve() / "stage"
        package_dir = pathlib.Path(self.get_ext_fullpath(ext.name)).resolve().parent
        configure = [
            "cmake", "-S", str(ROOT), "-B", str(build),
            "-DCMAKE_BUILD_TYPE=Release",
            "-DRAYFORGE_BUILD_TESTS=OFF", "-DRAYFORGE_BUILD_BENCHMARKS=OFF", "-DRAYFORGE_BUILD_APPS=OFF",
            f"-DPython3_EXECUTABLE={sys.executable}",
            # The package and the library in one folder: the module's RPATH is $ORIGIN.
            f"-DCMAKE_INSTALL_PREFIX={stage}", "-DRAYFORGE_PYTHON_INSTALL_DIR=.", "-DCMAKE_INSTALL_LIBDIR=rayforge",
        ] + shlex.split(os.environ.get("RAYFORGE_CMAKE_ARGS", ""))
        jobs = str(os.environ.get("RAYFORGE_JOBS", os.cpu_count() or 1))
        subprocess.run(configure, check=True)
        subprocess.run(["cmake", "--build", str(build), "--target", "_rayforge", "-j", jobs], check=True)
        shutil.rmtree(stage, ignore_errors=True)
        subprocess.run(["cmake", "--install", str(build)], check=True)
        package_dir.mkdir(parents=True, exist_ok=True)
        for item in (stage / "rayforge").iterdir():  # the module, the library, the package's Python files
            if re.fullmatch(r"lib\w+\.so(\.[\d.]+)?", item.name):
                # The library once, under its SONAME (what the module asks for); wheels hold no symlinks.
                if re.fullmatch(r"lib\w+\.so\.\d+", item.name):
                    shutil.copy2(item.resolve(), package_dir / item.name)
            elif item.is_file():
                shutil.copy2(item, package_dir / item.name)


setup(
    ext_modules=[CMakeExtension("rayforge._rayforge")],
    cmdclass={"build_ext": CMakeBuild},
    # Not ./build: that is the project's CMake build folder (scripts/build.sh).
    options={"build": {"build_base": "build-python"}},
)

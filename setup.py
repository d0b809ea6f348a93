"""The trbc Python package: trbc._core is built by the project's CMake (target trbc_python, in the
build directory the CLI uses, $TRBC_BUILD_DIR or ./build), and the package ships the data it needs
(surrogate networks, experimental data sets, example data) so that it works without the source tree.

Install with `make python` (a venv over Debian's python3, `pip install --no-build-isolation .`).
"""
import os
import shutil
import subprocess
import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
BUILD = Path(os.environ.get("TRBC_BUILD_DIR", ROOT / "build")).resolve()
BUILD.mkdir(parents=True, exist_ok=True)
DATA = [
    # branch.json: the branch classifier of a branched model (copied when present)
    ("surrogates", ["equilibrium.json", "stretching.json", "relaxation.json", "branch.json", "accuracy.json", "cv.json"]),
    # the flow networks (`trbc flow train`, data/README.md)
    ("surrogates/flow", ["flow_regime.json", "flow_tank_treading.json", "flow_surrogate.json", "training.json", "accuracy.md"]),
    ("experiments", None),  # the whole tree
    ("examples", None),
]


def project_version():
    for line in (ROOT / "CMakeLists.txt").read_text().splitlines():
        if line.startswith("project(trbc VERSION"):
            return line.split()[2]
    return "0.0.0"


class CMakeBuild(build_ext):
    """Builds the extension with CMake instead of setuptools' compiler driver."""

    def build_extension(self, ext):
        build = BUILD
        jobs = os.environ.get("TRBC_JOBS", str(os.cpu_count() or 1))
        if not (build / "CMakeCache.txt").exists():
            subprocess.check_call(["cmake", "-S", str(ROOT), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release",
                                   f"-DPython_EXECUTABLE={sys.executable}"])
        subprocess.check_call(["cmake", "--build", str(build), "--target", "trbc_python", "-j", jobs])
        name = Path(self.get_ext_filename(ext.name)).name
        built = build / "python" / "trbc" / name
        if not built.exists():
            raise RuntimeError(f"{built} was not built: is pybind11-dev installed (scripts/bootstrap)?")
        target = Path(self.get_ext_fullpath(ext.name))
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(built, target)


class BuildWithData(build_py):
    """Copies the shipped data into trbc/data of the built package."""

    def run(self):
        super().run()
        dest = Path(self.build_lib) / "trbc" / "data"
        for sub, files in DATA:
            src = ROOT / "data" / sub
            if files is None:
                shutil.copytree(src, dest / sub, dirs_exist_ok=True)
            else:
                (dest / sub).mkdir(parents=True, exist_ok=True)
                for f in files:
                    if not (src / f).exists() and f == "branch.json":
                        continue
                    shutil.copy2(src / f, dest / sub / f)


setup(
    name="trbc",
    version=project_version(),
    description="Calibrated red-blood-cell membrane model: Python API over the trbc C++ library",
    packages=["trbc"],
    package_dir={"trbc": "src/python/trbc"},
    ext_modules=[Extension("trbc._core", sources=[])],
    cmdclass={"build_ext": CMakeBuild, "build_py": BuildWithData},
    options={"build": {"build_base": str(BUILD / "setuptools")}, "egg_info": {"egg_base": str(BUILD)}},
    python_requires=">=3.8",
    zip_safe=False,
)

"""The PEP 517 build backend of the wheel `arbor-slam` (pyproject.toml, docs/python.md "The
wheel"): drives the CMake build offline and packs its result.

    /usr/bin/python3 -m build --no-isolation --wheel [-C build-dir=DIR] [-C cmake-args="..."]
    /usr/bin/python3 -m pip wheel --no-build-isolation --no-deps . [--config-settings ...]

build_wheel configures BUILD for the Python running the backend (BUILD: the config setting
`build-dir`, else build-wheel-cp311 in the source tree, as deep as build/ so that ccache can hit)
unless it already holds a CMakeCache.txt, then builds the target arbor_python and packs what
BUILD/python/wheel_files.txt lists (python/CMakeLists.txt): the extension module at the
wheel's root and our shared libraries in arbor_slam.libs/ under their SONAMEs; patchelf gives
the module the RUNPATH $ORIGIN/arbor_slam.libs and the libraries $ORIGIN, so no path of the
build machine remains.
The other libraries (SuiteSparse, OpenBLAS, ...) are the system's: the wheel is tagged
linux_x86_64, for machines with the build machine's Debian packages, not manylinux.
"""

import base64
import hashlib
import os
import re
import shlex
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import tomllib
import zipfile

SOURCE = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MODULE = "arbor_slam"
LIBS_DIR = MODULE + ".libs"


def _version():
    """The version's one home: project(arbor VERSION x.y.z) in the top CMakeLists.txt."""
    with open(os.path.join(SOURCE, "CMakeLists.txt"), encoding="utf-8") as f:
        match = re.search(r"project\(arbor\s+VERSION\s+([0-9.]+)", f.read())
    if not match:
        raise RuntimeError("no project(arbor VERSION ...) in CMakeLists.txt")
    return match.group(1)


def _project():
    with open(os.path.join(SOURCE, "pyproject.toml"), "rb") as f:
        return tomllib.load(f)["project"]


def _tag():
    """cp311-cp311-linux_x86_64: the extension is built for this interpreter's ABI."""
    if sys.implementation.name != "cpython":
        raise RuntimeError("the module is a CPython extension; run the backend with CPython")
    python = f"cp{sys.version_info.major}{sys.version_info.minor}"
    platform = re.sub(r"[-.]", "_", sysconfig.get_platform())
    return f"{python}-{python}{sys.abiflags}-{platform}"


def _metadata():
    project = _project()
    lines = [
        "Metadata-Version: 2.1",
        f"Name: {project['name']}",
        f"Version: {_version()}",
        f"Summary: {project['description']}",
        f"Requires-Python: {project['requires-python']}",
        f"License: {project['license']['text']}",
    ]
    lines += [f"Requires-Dist: {requirement}" for requirement in project["dependencies"]]
    readme = project.get("readme")
    if readme:
        lines.append("Description-Content-Type: text/markdown")
        with open(os.path.join(SOURCE, readme), encoding="utf-8") as f:
            return "\n".join(lines) + "\n\n" + f.read()
    return "\n".join(lines) + "\n"


def _settings(config_settings):
    config_settings = config_settings or {}
    default = os.path.join(SOURCE, "build-wheel-" + _tag().split("-")[0])  # build-wheel-cp311
    build_dir = config_settings.get("build-dir") or default
    cmake_args = config_settings.get("cmake-args") or ""
    if isinstance(cmake_args, list):  # pip passes a repeated setting as a list
        cmake_args = " ".join(cmake_args)
    return os.path.abspath(build_dir), shlex.split(cmake_args)


def _run(command):
    print("arbor_slam_backend:", shlex.join(command), flush=True)
    subprocess.run(command, check=True, stdout=sys.stderr)


def _build(build_dir, cmake_args):
    if not os.path.exists(os.path.join(build_dir, "CMakeCache.txt")):
        configure = ["cmake", "-S", SOURCE, "-B", build_dir, "-DCMAKE_BUILD_TYPE=Release",
                     "-DARBOR_PYTHON=ON", "-DARBOR_BUILD_TESTS=OFF",
                     "-DARBOR_BUILD_BENCHMARKS=OFF", f"-DPython3_EXECUTABLE={sys.executable}"]
        if shutil.which("ccache"):
            configure += ["-DCMAKE_C_COMPILER_LAUNCHER=ccache",
                          "-DCMAKE_CXX_COMPILER_LAUNCHER=ccache"]
        _run(configure + cmake_args)
    jobs = os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL") or str(os.cpu_count() or 1)
    _run(["cmake", "--build", build_dir, "--target", "arbor_python", "-j", jobs])
    with open(os.path.join(build_dir, "python", "wheel_files.txt"), encoding="utf-8") as f:
        lines = [line for line in f.read().splitlines() if line]
    module, libraries = lines[0], [line.split("\t") for line in lines[1:]]
    suffix = sysconfig.get_config_var("EXT_SUFFIX")
    if os.path.basename(module) != MODULE + suffix:
        raise RuntimeError(f"{build_dir} built {os.path.basename(module)}, not {MODULE}{suffix} "
                           f"for {sys.executable}: give another build-dir")
    return module, libraries


def _record_line(name, data):
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{name},sha256={digest},{len(data)}"


def _write_wheel(path, files):
    """files: (name in the wheel, bytes, executable). Entries dated 1980: the same inputs give
    the same wheel."""
    dist_info = f"{MODULE}-{_version()}.dist-info"
    wheel = f"Wheel-Version: 1.0\nGenerator: arbor_slam_backend\nRoot-Is-Purelib: false\n" \
            f"Tag: {_tag()}\n"
    files = files + [(f"{dist_info}/METADATA", _metadata().encode(), False),
                     (f"{dist_info}/WHEEL", wheel.encode(), False)]
    record = [_record_line(name, data) for name, data, _ in files] + [f"{dist_info}/RECORD,,"]
    files.append((f"{dist_info}/RECORD", ("\n".join(record) + "\n").encode(), False))
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data, executable in files:
            info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
            info.external_attr = (0o755 if executable else 0o644) << 16
            info.compress_type = zipfile.ZIP_DEFLATED
            z.writestr(info, data)


def _packed(module, libraries, stage):
    """Copies into stage and sets the RUNPATHs; returns the wheel's files."""
    os.makedirs(os.path.join(stage, LIBS_DIR))
    entries = [(os.path.basename(module), module, f"$ORIGIN/{LIBS_DIR}")]
    entries += [(f"{LIBS_DIR}/{soname}", library, "$ORIGIN") for library, soname in libraries]
    files = []
    for name, source, runpath in entries:
        target = os.path.join(stage, name)
        shutil.copyfile(source, target)
        _run(["patchelf", "--set-rpath", runpath, target])
        with open(target, "rb") as f:
            files.append((name, f.read(), True))
    return files


def get_requires_for_build_wheel(config_settings=None):
    return []  # cmake, a compiler and patchelf are Debian packages (scripts/install-deps.sh)


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    if not shutil.which("patchelf"):
        raise RuntimeError("the wheel needs patchelf (Debian: patchelf)")
    module, libraries = _build(*_settings(config_settings))
    name = f"{MODULE}-{_version()}-{_tag()}.whl"
    with tempfile.TemporaryDirectory() as stage:
        files = _packed(module, libraries, stage)
        _write_wheel(os.path.join(wheel_directory, name), files)
    return name
